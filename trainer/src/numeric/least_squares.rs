//! Linear least squares, min |A x − b|², the trainer's one implementation; never the normal
//! equations, which square the condition number.
//!
//! - [`QrLeastSquares`]: Householder QR for full-column-rank A. The factorisation is kept, so
//!   further right-hand sides for the same A cost O(rows · cols): the chord steps of the solver
//!   reuse one Jacobian's factorisation.
//! - [`TruncatedSvd`]: the SVD of the column-scaled A, for rank-deficient problems (DH
//!   calibration, the effect library): the minimum-norm solution over the identifiable
//!   directions, Levenberg–Marquardt steps, and the covariance factor (AᵀA)⁺.

use faer::dyn_stack::{MemBuffer, MemStack, StackReq};
use faer::linalg::qr::no_pivoting::factor;
use faer::linalg::{householder, triangular_solve};
use faer::{Conj, Mat, MatRef, Par};

/// A factorisation that failed: what the callers' errors carry as their source.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum LeastSquaresError {
    /// faer's SVD did not converge (non-finite entries in A, typically).
    #[error("SVD of the {rows} × {cols} matrix did not converge (non-finite entries?)")]
    SvdNoConvergence { rows: usize, cols: usize },
}

impl From<LeastSquaresError> for crate::Error {
    fn from(e: LeastSquaresError) -> crate::Error {
        crate::Error::stage("least squares", e)
    }
}

/// A = Q R, Householder vectors below the diagonal of `qr`, R on and above it.
pub struct QrLeastSquares {
    qr: Mat<f64>,
    h: Mat<f64>,
    par: Par,
}

impl QrLeastSquares {
    /// Factors `a` in place ([`Self::solve`] needs rows ≥ cols and full column rank). `par` only splits the work: the
    /// blocked algorithm's arithmetic does not depend on it.
    pub fn factor(mut a: Mat<f64>, par: Par) -> Self {
        let (rows, cols) = (a.nrows(), a.ncols());
        let block = factor::recommended_block_size::<f64>(rows, cols);
        let mut h = Mat::zeros(block, rows.min(cols));
        let mut mem = MemBuffer::new(factor::qr_in_place_scratch::<f64>(rows, cols, block, par, Default::default()));
        factor::qr_in_place(a.as_mut(), h.as_mut(), par, MemStack::new(&mut mem), Default::default());
        QrLeastSquares { qr: a, h, par }
    }

    /// |R_jj|, j < cols.
    pub fn r_diagonal(&self) -> Vec<f64> {
        (0..self.qr.ncols().min(self.qr.nrows())).map(|j| self.qr[(j, j)].abs()).collect()
    }

    /// The first `cols` columns of Q: an orthonormal basis of A's columns (rows × cols).
    pub fn thin_q(&self) -> Mat<f64> {
        let (rows, cols) = (self.qr.nrows(), self.qr.ncols());
        let mut q = Mat::from_fn(rows, cols, |i, j| if i == j { 1.0 } else { 0.0 });
        let req = householder::apply_block_householder_sequence_on_the_left_in_place_scratch::<f64>(rows, self.h.nrows(), cols);
        let mut mem = MemBuffer::new(req);
        householder::apply_block_householder_sequence_on_the_left_in_place_with_conj(
            self.qr.as_ref(),
            self.h.as_ref(),
            Conj::No,
            q.as_mut(),
            self.par,
            MemStack::new(&mut mem),
        );
        q
    }

    /// R (min(rows, cols) × cols, upper trapezoidal): min |A x − b|² = min |R x − (Qᵀb)[..]|² + const,
    /// so a problem on a subset of A's columns can be solved on R's columns instead of A's rows.
    pub fn r_factor(&self) -> Mat<f64> {
        let (k, cols) = (self.qr.nrows().min(self.qr.ncols()), self.qr.ncols());
        Mat::from_fn(k, cols, |i, j| if i <= j { self.qr[(i, j)] } else { 0.0 })
    }

    /// (Qᵀ b)[..min(rows, cols)]: the right-hand side that goes with [`Self::r_factor`].
    pub fn project(&self, b: &[f64]) -> Vec<f64> {
        let (rows, k) = (self.qr.nrows(), self.qr.nrows().min(self.qr.ncols()));
        let rhs = self.qt_times(b);
        debug_assert_eq!(rhs.nrows(), rows);
        (0..k).map(|i| rhs[(i, 0)]).collect()
    }

    /// Qᵀ b (rows × 1).
    fn qt_times(&self, b: &[f64]) -> Mat<f64> {
        let rows = self.qr.nrows();
        assert_eq!(b.len(), rows, "right-hand side length");
        let mut rhs = Mat::from_fn(rows, 1, |i, _| b[i]);
        let req: StackReq =
            householder::apply_block_householder_sequence_transpose_on_the_left_in_place_scratch::<f64>(rows, self.h.nrows(), 1);
        let mut mem = MemBuffer::new(req);
        householder::apply_block_householder_sequence_transpose_on_the_left_in_place_with_conj(
            self.qr.as_ref(),
            self.h.as_ref(),
            Conj::Yes,
            rhs.as_mut(),
            self.par,
            MemStack::new(&mut mem),
        );
        rhs
    }

    /// x = R⁻¹ (Qᵀ b)[..cols]; non-finite entries when R is singular to working precision.
    pub fn solve(&self, b: &[f64]) -> Vec<f64> {
        let cols = self.qr.ncols();
        let rhs = self.qt_times(b);
        let mut x = rhs.subrows(0, cols).to_owned();
        triangular_solve::solve_upper_triangular_in_place(self.qr.as_ref().subrows(0, cols), x.as_mut(), self.par);
        (0..cols).map(|i| x[(i, 0)]).collect()
    }
}

/// A D⁻¹ = U Σ Vᵀ (thin SVD), D = diag(column scales), σ_k non-increasing. Directions are kept
/// when σ_k² > `tolerance` · σ_max², i.e. the eigenvalues of the scaled AᵀA the callers' tolerances
/// are stated in; the others are unidentifiable and left out (minimum-norm, pseudo-inverse).
pub struct TruncatedSvd {
    scale: Vec<f64>,
    u: Mat<f64>,
    sigma: Vec<f64>,
    v: Mat<f64>,
}

impl TruncatedSvd {
    /// Columns scaled to unit norm (an all-zero column keeps scale `f64::MIN_POSITIVE`).
    pub fn unit_columns(a: MatRef<'_, f64>) -> Result<Self, LeastSquaresError> {
        let scale = (0..a.ncols()).map(|k| column_norm(a, k).max(f64::MIN_POSITIVE)).collect();
        Self::with_scales(a, scale)
    }

    /// Columns divided by `scale` (positive, one per column). A matrix with fewer rows than
    /// columns (fewer measured coordinates than parameters) is factored as itself padded with zero
    /// rows: the same AᵀA, and a singular value (zero for the directions the rows do not see) and a
    /// right singular vector for every column, which callers index by parameter.
    pub fn with_scales(a: MatRef<'_, f64>, scale: Vec<f64>) -> Result<Self, LeastSquaresError> {
        assert_eq!(scale.len(), a.ncols(), "one scale per column");
        let (rows, cols) = (a.nrows(), a.ncols());
        let scaled = Mat::from_fn(rows.max(cols), cols, |i, k| if i < rows { a[(i, k)] / scale[k] } else { 0.0 });
        let svd = scaled.thin_svd().map_err(|_| LeastSquaresError::SvdNoConvergence { rows, cols })?;
        let sigma = (0..svd.S().dim()).map(|k| svd.S()[k]).collect();
        // The padding rows of U meet only zeros of a right-hand side: drop them.
        Ok(TruncatedSvd { scale, u: svd.U().subrows(0, rows).to_owned(), sigma, v: svd.V().to_owned() })
    }

    /// The column scales D.
    pub fn scales(&self) -> &[f64] {
        &self.scale
    }

    /// σ_k² of the scaled matrix: the eigenvalues of D⁻¹AᵀAD⁻¹, largest first.
    pub fn eigenvalues(&self) -> Vec<f64> {
        self.sigma.iter().map(|s| s * s).collect()
    }

    /// Right singular vector k (scaled parameters).
    pub fn direction(&self, k: usize) -> Vec<f64> {
        (0..self.v.nrows()).map(|i| self.v[(i, k)]).collect()
    }

    /// Whether direction k is identifiable: σ_k² > tolerance · σ_max² (and σ_k > 0).
    pub fn keeps(&self, k: usize, tolerance: f64) -> bool {
        let (s, s_max) = (self.sigma[k], self.sigma.first().copied().unwrap_or(0.0));
        s > 0.0 && s * s > tolerance * s_max * s_max
    }

    /// u_kᵀ b for every k.
    fn projections(&self, b: &[f64]) -> Vec<f64> {
        assert_eq!(b.len(), self.u.nrows(), "right-hand side length");
        (0..self.u.ncols()).map(|k| (0..b.len()).map(|i| self.u[(i, k)] * b[i]).sum()).collect()
    }

    /// Minimum-norm least-squares solution over the kept directions, in A's (unscaled)
    /// parameters: x = D⁻¹ Σ_k v_k (u_kᵀ b) / σ_k.
    pub fn solve(&self, b: &[f64], tolerance: f64) -> Vec<f64> {
        let p = self.scale.len();
        let ub = self.projections(b);
        let mut x = vec![0.0; p];
        for (k, ub_k) in ub.iter().enumerate().filter(|&(k, _)| self.keeps(k, tolerance)) {
            let c = ub_k / self.sigma[k];
            for (i, x_i) in x.iter_mut().enumerate() {
                *x_i += c * self.v[(i, k)];
            }
        }
        x.iter().zip(&self.scale).map(|(x, d)| x / d).collect()
    }

    /// Levenberg–Marquardt step for the residual `r` (model − data) with damping μ on the scaled
    /// normal matrix, over the kept directions, in *scaled* parameters:
    /// δ = −Σ_k v_k σ_k (u_kᵀ r) / (σ_k² + μ), and the decrease of ½|r + A D⁻¹ δ|² the linear model
    /// predicts, −Σ_k (c_k σ_k u_kᵀr + ½ σ_k² c_k²) with c_k the step's coefficient.
    pub fn damped_step(&self, r: &[f64], mu: f64, tolerance: f64) -> (Vec<f64>, f64) {
        let p = self.scale.len();
        let ur = self.projections(r);
        let (mut step, mut predicted) = (vec![0.0; p], 0.0);
        for (k, ur_k) in ur.iter().enumerate().filter(|&(k, _)| self.keeps(k, tolerance)) {
            let (s, g_k) = (self.sigma[k], self.sigma[k] * ur_k);
            let c = -g_k / (s * s + mu);
            predicted -= c * g_k + 0.5 * s * s * c * c;
            for (i, d) in step.iter_mut().enumerate() {
                *d += c * self.v[(i, k)];
            }
        }
        (step, predicted)
    }

    /// (AᵀA)⁺ over the kept directions, unscaled (p × p, row-major): D⁻¹ (Σ_k v_k v_kᵀ / σ_k²) D⁻¹,
    /// the Gauss–Newton covariance up to σ̂².
    pub fn gram_pseudo_inverse(&self, tolerance: f64) -> Vec<f64> {
        let p = self.scale.len();
        let mut out = vec![0.0; p * p];
        for k in (0..self.sigma.len()).filter(|&k| self.keeps(k, tolerance)) {
            let l = self.sigma[k] * self.sigma[k];
            for i in 0..p {
                for j in 0..p {
                    out[i * p + j] += self.v[(i, k)] * self.v[(j, k)] / l;
                }
            }
        }
        (0..p * p).map(|ij| out[ij] / (self.scale[ij / p] * self.scale[ij % p])).collect()
    }
}

/// |A e_k|.
pub fn column_norm(a: MatRef<'_, f64>, k: usize) -> f64 {
    (0..a.nrows()).map(|i| a[(i, k)].powi(2)).sum::<f64>().sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A deterministic, well-conditioned tall matrix with a known least-squares solution:
    /// b = A x* + r with r orthogonal to A's columns (r built from the last rows, where A is zero).
    fn problem(rows: usize, cols: usize) -> (Mat<f64>, Vec<f64>, Vec<f64>) {
        let a = Mat::from_fn(rows, cols, |i, j| {
            if i >= rows - 3 {
                0.0
            } else {
                ((i * 7 + j * 13) % 17) as f64 / 17.0 - 0.5 + if i == j { 3.0 } else { 0.0 }
            }
        });
        let x: Vec<f64> = (0..cols).map(|j| (j as f64 * 0.37).sin()).collect();
        let b: Vec<f64> =
            (0..rows).map(|i| (0..cols).map(|j| a[(i, j)] * x[j]).sum::<f64>() + if i >= rows - 3 { 1.0 } else { 0.0 }).collect();
        (a, b, x)
    }

    #[test]
    fn solves_a_known_least_squares_problem() {
        // The second size takes faer's blocked path (block size 64 or more).
        for (rows, cols) in [(40, 25), (4096, 2048)] {
            let (a, b, x) = problem(rows, cols);
            let got = QrLeastSquares::factor(a, Par::rayon(2)).solve(&b);
            let worst = got.iter().zip(&x).fold(0.0f64, |w, (g, e)| w.max((g - e).abs()));
            assert!(worst < 1e-10, "{rows}x{cols}: {worst:e}");
        }
    }

    /// Results independent of the thread count (blobs must be byte-identical with 1 and 2
    /// threads): faer's split `Par::rayon(2)` fixes the arithmetic (it differs from `Par::Seq`'s),
    /// whatever number of threads the pool running it has. Large enough for faer to split the work.
    #[test]
    fn fixed_split_gives_the_same_bits_on_one_or_two_threads() {
        let (a, b, _) = problem(1200, 600);
        let on = |threads: usize| {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
            pool.install(|| QrLeastSquares::factor(a.clone(), Par::rayon(2)).solve(&b))
        };
        let (one, two, two_again) = (on(1), on(2), on(2));
        assert!(one == two, "1 vs 2 threads");
        assert!(two == two_again, "run to run");
    }

    /// A rank-deficient problem (column 2 = column 0 + column 1): the truncated solution is the
    /// minimum-norm one in scaled parameters, reproduces the fitted values, and (AᵀA)⁺ is the
    /// Moore–Penrose inverse of the scaled Gram matrix.
    #[test]
    fn truncated_svd_handles_a_rank_deficient_problem() {
        let rows = 30;
        let a = Mat::from_fn(rows, 3, |i, j| {
            let (c0, c1) = ((i as f64 * 0.7).sin(), (i as f64 * 1.3).cos());
            [c0, c1, c0 + c1][j]
        });
        let b: Vec<f64> = (0..rows).map(|i| 2.0 * a[(i, 0)] - a[(i, 1)] + 0.01 * (i as f64).sin()).collect();
        let svd = TruncatedSvd::with_scales(a.as_ref(), vec![1.0; 3]).unwrap();
        assert!(svd.keeps(1, 1e-12) && !svd.keeps(2, 1e-12));
        let x = svd.solve(&b, 1e-12);
        // Minimum norm: x is orthogonal to the null direction (1, 1, −1).
        assert!((x[0] + x[1] - x[2]).abs() < 1e-10, "{x:?}");
        // The fit equals the full-rank fit on columns 0 and 1.
        let two = QrLeastSquares::factor(Mat::from_fn(rows, 2, |i, j| a[(i, j)]), Par::Seq).solve(&b);
        for i in 0..rows {
            let (f3, f2) = ((0..3).map(|j| a[(i, j)] * x[j]).sum::<f64>(), a[(i, 0)] * two[0] + a[(i, 1)] * two[1]);
            assert!((f3 - f2).abs() < 1e-10);
        }
        // G G⁺ G = G for G = AᵀA.
        let g = a.transpose() * &a;
        let pinv = svd.gram_pseudo_inverse(1e-12);
        let pm = Mat::from_fn(3, 3, |i, j| pinv[i * 3 + j]);
        let ggg = &g * &pm * &g;
        for i in 0..3 {
            for j in 0..3 {
                assert!((ggg[(i, j)] - g[(i, j)]).abs() < 1e-9 * (1.0 + g[(i, j)].abs()));
            }
        }
    }

    /// Issue 27 item 1: fewer rows than columns (a DH fit on 10 three-coordinate rows has 30
    /// residuals for 33 parameters) indexed past the thin SVD's min(rows, cols) singular values.
    /// Every column now has a direction; those the rows cannot see are zero and never kept.
    #[test]
    fn wide_matrix_has_a_direction_per_column() {
        let (rows, cols) = (4, 7);
        let a = Mat::from_fn(rows, cols, |i, j| ((i * 5 + j * 3) % 11) as f64 / 11.0 + if i == j { 1.0 } else { 0.0 });
        let svd = TruncatedSvd::unit_columns(a.as_ref()).unwrap();
        assert_eq!(svd.eigenvalues().len(), cols);
        let kept = (0..cols).filter(|&k| svd.keeps(k, 1e-12)).count();
        assert_eq!(kept, rows);
        assert!((0..cols).all(|k| svd.direction(k).len() == cols));
        // The minimum-norm solution reproduces b exactly (A has full row rank).
        let b: Vec<f64> = (0..rows).map(|i| (i as f64).cos()).collect();
        let x = svd.solve(&b, 1e-12);
        for i in 0..rows {
            let fitted: f64 = (0..cols).map(|j| a[(i, j)] * x[j]).sum();
            assert!((fitted - b[i]).abs() < 1e-12, "{fitted} vs {}", b[i]);
        }
        let (step, _) = svd.damped_step(&b, 0.0, 1e-12);
        assert_eq!(step.len(), cols);
        assert_eq!(svd.gram_pseudo_inverse(1e-12).len(), cols * cols);
    }

    /// With μ → 0 the damped step is the Gauss–Newton step −x of the truncated solve (residual r =
    /// −b), and the predicted decrease is ½ of the explained sum of squares.
    #[test]
    fn damped_step_tends_to_the_gauss_newton_step() {
        let (a, b, _) = problem(40, 5);
        let svd = TruncatedSvd::unit_columns(a.as_ref()).unwrap();
        let x = svd.solve(&b, 1e-14);
        let r: Vec<f64> = b.iter().map(|v| -v).collect();
        let (step, predicted) = svd.damped_step(&r, 0.0, 1e-14);
        for ((s, x), d) in step.iter().zip(&x).zip(svd.scales()) {
            assert!((s / d - x).abs() < 1e-10, "{} vs {x}", s / d);
        }
        let fitted: Vec<f64> = (0..40).map(|i| (0..5).map(|j| a[(i, j)] * x[j]).sum::<f64>()).collect();
        let explained = 0.5 * fitted.iter().map(|f| f * f).sum::<f64>();
        assert!((predicted - explained).abs() < 1e-9 * explained);
    }
}

//! min |A x − b|² by Householder QR (never the normal equations, which square the condition number).
//! The factorisation is kept, so further right-hand sides for the same A cost O(rows · cols):
//! the chord steps of the solver reuse one Jacobian's factorisation.

use faer::dyn_stack::{MemBuffer, MemStack, StackReq};
use faer::linalg::qr::no_pivoting::factor;
use faer::linalg::{householder, triangular_solve};
use faer::{Conj, Mat, Par};

/// A = Q R, Householder vectors below the diagonal of `qr`, R on and above it.
pub struct QrLeastSquares {
    qr: Mat<f64>,
    h: Mat<f64>,
    par: Par,
}

impl QrLeastSquares {
    /// Factors `a` (rows ≥ cols, full column rank) in place. `par` only splits the work: the
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

    /// x = R⁻¹ (Qᵀ b)[..cols]; non-finite entries when R is singular to working precision.
    pub fn solve(&self, b: &[f64]) -> Vec<f64> {
        let (rows, cols) = (self.qr.nrows(), self.qr.ncols());
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
        let mut x = rhs.subrows(0, cols).to_owned();
        triangular_solve::solve_upper_triangular_in_place(self.qr.as_ref().subrows(0, cols), x.as_mut(), self.par);
        (0..cols).map(|i| x[(i, 0)]).collect()
    }
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
}

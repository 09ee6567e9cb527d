//! The (damped) Gauss–Newton step of energy (16) as one least-squares problem:
//! min_δ |J δ/σ + r|² + (P + δ)ᵀ K (P + δ) + δᵀ (μ I + λ D²) δ,  D² = diag(JᵀJ/σ² + K),
//! solved by QR of [J/σ; Lᵀ] with L Lᵀ = K + μ I + λ D² (never JᵀJ: that would square J's condition).
//! The regulariser and damping terms combine exactly: with M = L Lᵀ,
//! Pᵀ K P + 2 δᵀ K P + δᵀ M δ = |Lᵀ δ + L⁻¹ K P|² + const, so the damping costs no extra rows.

use crate::numeric::least_squares::QrLeastSquares;
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::llt::factor::{cholesky_in_place, cholesky_in_place_scratch};
use faer::linalg::matmul::matmul;
use faer::linalg::triangular_solve::solve_lower_triangular_in_place;
use faer::{Accum, Mat, Par};

/// The factorisation behind steps with one Jacobian and one damping; reusable for any residual
/// and P (chord steps).
pub struct StepFactor {
    pub damping: f64,
    /// Lᵀ, upper triangular.
    lt: Mat<f64>,
    qr: QrLeastSquares,
}

/// Lᵀ with L Lᵀ = K + diag(shift) + μ·mean(diag K)·I. μ starts at `proximal` and grows tenfold until the
/// factorisation succeeds: kernel matrices of distinct points are positive definite but numerically
/// singular. μ|δ|² is a proximal term (it vanishes at a fixed point, δ = 0).
/// `par` is explicit (faer's global default follows the pool's thread count, which would make the
/// rounding depend on it).
fn factor_metric(k: &Mat<f64>, shift: Option<&[f64]>, proximal: f64, par: Par) -> Option<Mat<f64>> {
    let dim = k.nrows();
    let mean_diag = (0..dim).map(|i| k[(i, i)]).sum::<f64>() / dim as f64;
    let mut jitter = proximal * mean_diag;
    let mut mem = MemBuffer::new(cholesky_in_place_scratch::<f64>(dim, par, Default::default()));
    for _ in 0..8 {
        let mut kj = k.clone();
        for i in 0..dim {
            kj[(i, i)] += jitter + shift.map_or(0.0, |s| s[i]);
        }
        if cholesky_in_place(kj.as_mut(), Default::default(), par, MemStack::new(&mut mem), Default::default()).is_ok() {
            // L is in the lower triangle; Lᵀ, upper triangular.
            return Some(Mat::from_fn(dim, dim, |r, c| if r <= c { kj[(c, r)] } else { 0.0 }));
        }
        jitter *= 10.0;
    }
    None
}

/// How the damping term λ |D δ|² weighs the parameters.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DampingScale {
    /// D² = diag(JᵀJ/σ² + K) (Marquardt): each parameter by its own curvature.
    PerParameter,
    /// D² = mean of diag(JᵀJ/σ² + K) · I (Levenberg, scaled): a ball. For orthonormal coordinates
    /// of the momenta (the eigenspace) this is the same ball in momentum space for every direction,
    /// as `PerParameter` nearly is for the momenta themselves (their curvatures are alike), whereas
    /// per-direction scaling would let the weakly regularised eigen-directions take long steps.
    Uniform,
}

/// λ D² (see [`DampingScale`]).
fn marquardt_shift(jac: &Mat<f64>, k: &Mat<f64>, sigma: f64, damping: f64, scale: DampingScale) -> Vec<f64> {
    let per: Vec<f64> =
        (0..jac.ncols()).map(|c| damping * (jac.col(c).iter().map(|v| (v / sigma).powi(2)).sum::<f64>() + k[(c, c)])).collect();
    match scale {
        DampingScale::PerParameter => per,
        DampingScale::Uniform => {
            let mean = per.iter().sum::<f64>() / per.len().max(1) as f64;
            vec![mean; per.len()]
        }
    }
}

impl StepFactor {
    /// Factors the step for Jacobian `jac` (internal units; outputs × parameters, at least as many
    /// outputs as parameters is not required) and damping `damping` (0: Gauss–Newton).
    /// None when K + shifts cannot be factored.
    pub fn new(jac: &Mat<f64>, k: &Mat<f64>, sigma: f64, damping: f64, scale: DampingScale, proximal: f64, par: Par) -> Option<Self> {
        let shift = (damping > 0.0).then(|| marquardt_shift(jac, k, sigma, damping, scale));
        let lt = factor_metric(k, shift.as_deref(), proximal, par)?;
        let (outputs, dim) = (jac.nrows(), jac.ncols());
        let stacked = Mat::from_fn(outputs + dim, dim, |r, c| if r < outputs { jac[(r, c)] / sigma } else { lt[(r - outputs, c)] });
        Some(StepFactor { damping, lt, qr: QrLeastSquares::factor(stacked, par) })
    }

    /// δ for the current momenta `p` and scaled residual `residual` = (k1 − y)/σ: the solution of
    /// [J/σ; Lᵀ] δ ≈ [−r; −L⁻¹ K P].
    pub fn step(&self, k: &Mat<f64>, residual: &[f64], p: &[f64]) -> Vec<f64> {
        let dim = p.len();
        let pm = Mat::from_fn(dim, 1, |i, _| p[i]);
        let mut kp = Mat::zeros(dim, 1);
        matmul(kp.as_mut(), Accum::Replace, k.as_ref(), pm.as_ref(), 1.0, Par::Seq);
        solve_lower_triangular_in_place(self.lt.transpose(), kp.as_mut(), Par::Seq);
        let rhs: Vec<f64> = residual.iter().map(|r| -r).chain((0..dim).map(|i| -kp[(i, 0)])).collect();
        self.qr.solve(&rhs)
    }
}

/// (K + σ² I)⁻¹ r by Cholesky on the fixed split `par`: the linearised model's optimum (the
/// Gaussian-process posterior's coefficients) when the flow's response at P0 = 0 is K itself.
/// Kernel matrices the evidence picks can be singular to working precision next to σ²; then a jitter
/// from 1e-15 · mean diag K, tenfold per failure, makes the factorisation succeed.
pub fn solve_regularised(k: &Mat<f64>, sigma: f64, r: &[f64], par: Par) -> Option<Vec<f64>> {
    let dim = k.nrows();
    let mean_diag = (0..dim).map(|i| k[(i, i)]).sum::<f64>() / dim.max(1) as f64;
    let mut jitter = 0.0;
    let mut mem = MemBuffer::new(cholesky_in_place_scratch::<f64>(dim, par, Default::default()));
    for _ in 0..8 {
        let mut kj = k.clone();
        for i in 0..dim {
            kj[(i, i)] += sigma * sigma + jitter;
        }
        if cholesky_in_place(kj.as_mut(), Default::default(), par, MemStack::new(&mut mem), Default::default()).is_ok() {
            let mut x = Mat::from_fn(dim, 1, |i, _| r[i]);
            let l = kj.as_ref();
            solve_lower_triangular_in_place(l, x.as_mut(), par);
            faer::linalg::triangular_solve::solve_upper_triangular_in_place(l.transpose(), x.as_mut(), par);
            return Some((0..dim).map(|i| x[(i, 0)]).collect());
        }
        jitter = if jitter == 0.0 { 1e-15 * mean_diag } else { jitter * 10.0 };
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The step minimises the stated quadratic: its gradient there vanishes,
    /// Jᵀ(J δ/σ + r)/σ + K (P + δ) + (μ' I + λ D²) δ = 0 (μ' = μ·mean diag K), for both damping
    /// scales and for more outputs than parameters (the eigenspace's Jacobians).
    #[test]
    fn step_zeroes_the_gradient_of_the_damped_model() {
        for (outputs, dim) in [(12, 12), (20, 7)] {
            for scale_kind in [DampingScale::PerParameter, DampingScale::Uniform] {
                let jac = Mat::from_fn(outputs, dim, |i, j| ((i * 5 + j * 3) % 7) as f64 * 0.1 + if i == j { 1.0 } else { 0.0 });
                let k = Mat::from_fn(dim, dim, |i, j| (-((i as f64 - j as f64).powi(2)) / 8.0).exp());
                let (sigma, damping, proximal) = (1e-2, 1e-3, 1e-6);
                let residual: Vec<f64> = (0..outputs).map(|i| (i as f64 * 0.7).cos()).collect();
                let p: Vec<f64> = (0..dim).map(|i| (i as f64 * 0.3).sin()).collect();
                let f = StepFactor::new(&jac, &k, sigma, damping, scale_kind, proximal, Par::Seq).unwrap();
                let d = f.step(&k, &residual, &p);
                let mean_diag = (0..dim).map(|i| k[(i, i)]).sum::<f64>() / dim as f64;
                let shift = marquardt_shift(&jac, &k, sigma, damping, scale_kind);
                if scale_kind == DampingScale::Uniform {
                    assert!(shift.iter().all(|v| *v == shift[0]));
                }
                let model_residual: Vec<f64> =
                    (0..outputs).map(|r| (0..dim).map(|c| jac[(r, c)] * d[c]).sum::<f64>() / sigma + residual[r]).collect();
                let mut worst: f64 = 0.0;
                for c in 0..dim {
                    let g = (0..outputs).map(|r| jac[(r, c)] * model_residual[r]).sum::<f64>() / sigma
                        + (0..dim).map(|j| k[(c, j)] * (p[j] + d[j])).sum::<f64>()
                        + (proximal * mean_diag + shift[c]) * d[c];
                    worst = worst.max(g.abs());
                }
                let scale = (0..outputs).map(|r| residual[r].abs()).fold(0.0, f64::max) / sigma;
                assert!(worst < 1e-9 * scale, "{outputs}x{dim} {scale_kind:?}: gradient {worst:e} (scale {scale:e})");
            }
        }
    }
}

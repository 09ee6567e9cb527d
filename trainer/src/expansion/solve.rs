//! The linear model's weights in the expansion (docs/DESIGN.md §11): one Euler step,
//! k1(x) = k0(x) + w(k0(x)) − Dk0(x) v(x), with v = Σ_f φ_f c_f (c_f ~ N(0, γ λ_f) per component) and
//! w = Σ_g ψ_g d_g (d_g ~ N(0, 1)): the Gaussian process of DESIGN §3 in weight space. Its posterior
//! mean solves min |r − A w|² + σ² |Λ^{−1/2} w|², here by Householder QR of the whitened, stacked
//! [A Λ^{1/2}; σ I] — never the momenta, which cancel, and never the normal equations.

use super::basis::Basis;
use crate::numeric::least_squares::QrLeastSquares;
use crate::numeric::FIXED_SPLIT;
use cbd_protocol::{JointKernel, TaskKernel, MAX_TASK_DIM};
use cbd_runtime::internals::expansion::{for_each_task_basis, joint_row_len, write_joint_basis};
use cbd_runtime::internals::flow::Dims;
use faer::Mat;

/// The data of the linear fit, internal units: configurations, k0 and Dk0 at each, residual y − k0.
pub struct LinearProblem<'a> {
    pub dims: Dims,
    /// N × n configurations.
    pub points: &'a [f64],
    /// N × m nominal positions k0(x_i).
    pub nominal: &'a [f64],
    /// N × m × n nominal Jacobians Dk0(x_i), row-major per point.
    pub jacobians: &'a [f64],
    /// N × m residual y_i − k0(x_i).
    pub residual: &'a [f64],
}

/// The design matrix A (N·m × W): column f·n + e is −Dk0[:, e] φ_f (joint weight c_f[e]), column
/// r_V·n + g·m + c is ψ_g e_c (task weight d_g[c]), both through the runtime's own basis functions.
pub fn design(p: &LinearProblem<'_>, joint_kernel: &JointKernel, task_kernel: &TaskKernel, joint: &Basis, task: &Basis) -> Mat<f64> {
    let (m, n) = (p.dims.m, p.dims.n);
    let (r_v, r_w) = (joint.len(), task.len());
    let exponents = task_exponents(task);
    let rows = p.points.len() / n;
    let mut a = Mat::zeros(rows * m, r_v * n + r_w * m);
    let row_len = joint_row_len(n);
    let mut basis = vec![0.0; r_v * row_len];
    for i in 0..rows {
        let x = &p.points[i * n..(i + 1) * n];
        write_joint_basis(joint_kernel, &joint.codes, n, x, &mut basis, false);
        let jac = &p.jacobians[i * m * n..(i + 1) * m * n];
        for f in 0..r_v {
            let phi = basis[f * row_len];
            for e in 0..n {
                for c in 0..m {
                    a[(i * m + c, f * n + e)] = -jac[c * n + e] * phi;
                }
            }
        }
        let mut y = [0.0; MAX_TASK_DIM];
        y[..m].copy_from_slice(&p.nominal[i * m..(i + 1) * m]);
        for_each_task_basis(task_kernel, &exponents, m, &y[..m], false, |g, psi, _, _| {
            for c in 0..m {
                a[(i * m + c, r_v * n + g * m + c)] = psi;
            }
        });
    }
    a
}

/// The task basis's exponents (r_W × m) from its codes (`k << 1`).
pub fn task_exponents(task: &Basis) -> Vec<u8> {
    task.codes.iter().map(|c| c >> 1).collect()
}

/// Prior variance of every weight, in the order of [`design`]'s columns.
pub fn prior_variances(joint_gamma: f64, n: usize, m: usize, joint: &Basis, task: &Basis) -> Vec<f64> {
    let joint_part = joint.variances.iter().flat_map(|v| std::iter::repeat_n(joint_gamma * v, n));
    let task_part = task.variances.iter().flat_map(|v| std::iter::repeat_n(*v, m));
    joint_part.chain(task_part).collect()
}

/// The posterior-mean weights: w = Λ^{1/2} w', w' = argmin |r − A Λ^{1/2} w'|² + σ² |w'|²;
/// `None` if the factorisation is singular (it cannot be for σ > 0 unless A holds non-finite values).
pub fn posterior_weights(a: &Mat<f64>, variances: &[f64], sigma: f64, residual: &[f64]) -> Option<Vec<f64>> {
    let (rows, cols) = (a.nrows(), a.ncols());
    let scale: Vec<f64> = variances.iter().map(|v| v.sqrt()).collect();
    let stacked = Mat::from_fn(rows + cols, cols, |i, j| {
        if i < rows {
            a[(i, j)] * scale[j]
        } else if i - rows == j {
            sigma
        } else {
            0.0
        }
    });
    let mut rhs = residual.to_vec();
    rhs.resize(rows + cols, 0.0);
    let whitened = QrLeastSquares::factor(stacked, FIXED_SPLIT).solve(&rhs);
    let w: Vec<f64> = whitened.iter().zip(&scale).map(|(w, s)| w * s).collect();
    w.iter().all(|v| v.is_finite()).then_some(w)
}

/// A w: the fitted deformation at the design's rows.
pub fn apply(a: &Mat<f64>, w: &[f64]) -> Vec<f64> {
    (0..a.nrows()).map(|i| (0..a.ncols()).fold(0.0, |s, j| s + a[(i, j)] * w[j])).collect()
}

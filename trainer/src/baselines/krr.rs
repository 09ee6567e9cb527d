//! Kernel ridge regression (the Gaussian-process posterior mean) of the residual y − k0(x):
//! ŷ(x) = k0(x) + Σ_i K(x, x_i) α_i, (K + λ I) α = y − k0(x).

use crate::data::Measurements;
use cbd_protocol::{JointKernel, NominalModel, MAX_JOINTS};
use cbd_runtime::kernel::joint_kernel;
use cbd_runtime::nominal::forward_kinematics;
use faer::{linalg::solvers::Solve, Mat, Side};

/// A fitted residual regression: one scalar-kernel regression per task coordinate.
#[derive(Debug, Clone)]
pub struct KernelRidge {
    pub kernel: JointKernel,
    pub ridge: f64,
    points: Vec<f64>,
    n_joints: usize,
    task_dim: usize,
    /// N × m coefficients.
    alpha: Vec<f64>,
}

#[derive(Debug, Clone, PartialEq)]
pub enum KrrError {
    /// The kernel matrix plus ridge is not positive definite (duplicate points with ridge 0?).
    NotPositiveDefinite { n: usize, ridge: f64 },
}

impl std::fmt::Display for KrrError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            KrrError::NotPositiveDefinite { n, ridge } => {
                write!(f, "kernel ridge regression: the {n}×{n} kernel matrix plus ridge {ridge:e} is not positive definite")
            }
        }
    }
}

/// The N × N joint-kernel matrix K(x_i, x_j).
pub fn kernel_matrix(kernel: &JointKernel, a: &[f64], b: &[f64], n_joints: usize) -> Mat<f64> {
    let mut g = [0.0; MAX_JOINTS];
    Mat::from_fn(a.len() / n_joints, b.len() / n_joints, |i, j| {
        joint_kernel(kernel, &a[i * n_joints..(i + 1) * n_joints], &b[j * n_joints..(j + 1) * n_joints], &mut g)
    })
}

impl KernelRidge {
    pub fn fit(nominal: &NominalModel, data: &Measurements, kernel: JointKernel, ridge: f64) -> Result<Self, KrrError> {
        let (n, m, count) = (data.n_joints, data.task_dim, data.len());
        let mut k = kernel_matrix(&kernel, &data.joints, &data.joints, n);
        for i in 0..count {
            k[(i, i)] += ridge;
        }
        let rhs = Mat::from_fn(count, m, |i, c| data.position(i)[c] - forward_kinematics(nominal, data.joints(i)).position[c]);
        let llt = k.llt(Side::Lower).map_err(|_| KrrError::NotPositiveDefinite { n: count, ridge })?;
        let sol = llt.solve(&rhs);
        let alpha = (0..count).flat_map(|i| (0..m).map(move |c| (i, c))).map(|(i, c)| sol[(i, c)]).collect();
        Ok(KernelRidge { kernel, ridge, points: data.joints.clone(), n_joints: n, task_dim: m, alpha })
    }

    /// Corrected positions at `joints` (row-major), nominal plus regressed residual.
    pub fn predict(&self, nominal: &NominalModel, joints: &[f64]) -> Vec<f64> {
        let (n, m) = (self.n_joints, self.task_dim);
        let mut g = [0.0; MAX_JOINTS];
        let mut out = Vec::with_capacity(joints.len() / n * m);
        for q in joints.chunks_exact(n) {
            let k0 = forward_kinematics(nominal, q);
            let mut y = [0.0; 3];
            y[..m].copy_from_slice(&k0.position[..m]);
            for (xi, a) in self.points.chunks_exact(n).zip(self.alpha.chunks_exact(m)) {
                let kv = joint_kernel(&self.kernel, q, xi, &mut g);
                for c in 0..m {
                    y[c] += kv * a[c];
                }
            }
            out.extend_from_slice(&y[..m]);
        }
        out
    }
}

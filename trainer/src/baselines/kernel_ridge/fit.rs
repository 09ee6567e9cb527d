//! Kernel ridge regression (the Gaussian-process posterior mean) of the residual y − k0(x):
//! ŷ(x) = k0(x) + Σ_i K(x, x_i) α_i, (K + λ I) α = y − k0(x).

use crate::data::Measurements;
use cbd_protocol::{JointKernel, NominalModel, MAX_JOINTS};
use cbd_runtime::internals::kernel::{
    joint_features, joint_kernel, joint_kernel_from_features, read_features, write_features, FEATURES_PER_JOINT,
};
use cbd_runtime::internals::kinematics::{forward_kinematics, Kinematics};
use faer::{linalg::solvers::Solve, Mat, Side};

/// A fitted residual regression: one scalar-kernel regression per task coordinate.
#[derive(Debug, Clone)]
pub struct KernelRidge {
    pub kernel: JointKernel,
    pub ridge: f64,
    /// The training configurations' kernel features (`cbd_runtime::internals::kernel::write_features`):
    /// a prediction costs one `exp` per point, as the runtime's flow does.
    features: Vec<f64>,
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

impl std::error::Error for KrrError {}

impl From<KrrError> for crate::Error {
    fn from(e: KrrError) -> crate::Error {
        crate::Error::stage("kernel ridge", e)
    }
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
        let mut features = vec![0.0; count * n * FEATURES_PER_JOINT];
        write_features(&kernel, n, &data.joints, &mut features);
        Ok(KernelRidge { kernel, ridge, features, n_joints: n, task_dim: m, alpha })
    }

    /// The corrected position at `q` and its Jacobian: k0(q) + Σ_i K(q, x_i) α_i and
    /// Dk0(q) + Σ_i α_i ∇K(q, x_i)ᵀ.
    pub fn evaluate(&self, nominal: &NominalModel, q: &[f64]) -> Kinematics {
        let (n, m) = (self.n_joints, self.task_dim);
        let mut out = forward_kinematics(nominal, q);
        let mut fq = [[0.0; FEATURES_PER_JOINT]; MAX_JOINTS];
        joint_features(&self.kernel, q, &mut fq);
        let mut g = [0.0; MAX_JOINTS];
        for (i, a) in self.alpha.chunks_exact(m).enumerate() {
            let fx = read_features(&self.features, n, i);
            let kv = joint_kernel_from_features(&self.kernel, &fq[..n], &fx[..n], &mut g);
            for c in 0..m {
                out.position[c] += kv * a[c];
                for (jac, gd) in out.jacobian[c].iter_mut().zip(&g[..n]) {
                    *jac += a[c] * gd;
                }
            }
        }
        out
    }

    /// Corrected positions at `joints` (row-major), nominal plus regressed residual.
    pub fn predict(&self, nominal: &NominalModel, joints: &[f64]) -> Vec<f64> {
        let m = self.task_dim;
        joints.chunks_exact(self.n_joints).flat_map(|q| self.evaluate(nominal, q).position.into_iter().take(m)).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::simulate::{configurations, rr, Sampling};

    #[test]
    fn fits_the_training_points_and_its_jacobian_matches_finite_differences() {
        let real = rr::RealRr::default();
        let train = real.measure(&configurations(Sampling::Grid { per_axis: 8 }, 2));
        let mut kernel = cbd_protocol::paper_rr::joint_kernel();
        kernel.gamma = 1.0;
        let nominal = rr::nominal();
        let krr = KernelRidge::fit(&nominal, &train, kernel.clone(), 1e-10).unwrap();
        // Interpolates its training data (ridge 1e-10).
        let fitted = krr.predict(&nominal, &train.joints);
        let worst = fitted.iter().zip(&train.positions).fold(0.0f64, |w, (a, b)| w.max((a - b).abs()));
        assert!(worst < 1e-6, "{worst:e}");
        // The prediction equals k0 + Σ K(q, x_i) α_i with the direct kernel.
        let q = [0.37, -2.1];
        let e = krr.evaluate(&nominal, &q);
        let mut g = [0.0; MAX_JOINTS];
        let mut direct = forward_kinematics(&nominal, &q).position;
        for (i, a) in krr.alpha.chunks_exact(2).enumerate() {
            let kv = joint_kernel(&kernel, &q, train.joints(i), &mut g);
            direct[0] += kv * a[0];
            direct[1] += kv * a[1];
        }
        assert!((direct[0] - e.position[0]).abs() < 1e-12 && (direct[1] - e.position[1]).abs() < 1e-12);
        // Jacobian against central differences.
        let h = 1e-6;
        for d in 0..2 {
            let (mut qa, mut qb) = (q, q);
            qa[d] += h;
            qb[d] -= h;
            let (a, b) = (krr.evaluate(&nominal, &qa).position, krr.evaluate(&nominal, &qb).position);
            for c in 0..2 {
                let fd = (a[c] - b[c]) / (2.0 * h);
                assert!((fd - e.jacobian[c][d]).abs() < 1e-6 * (1.0 + fd.abs()), "row {c} joint {d}: {fd} vs {}", e.jacobian[c][d]);
            }
        }
    }
}

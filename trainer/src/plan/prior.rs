//! The Gaussian process's hyperparameters for planning: CbD's own evidence on the poses measured so
//! far (after the DH fit, as `cbd fit --dh-first` and `compare`'s dh+cbd choose them), or before any
//! data a stated prior (docs/DESIGN.md §13).

use crate::data::Measurements;
use crate::evidence::{choose_cbd_hyperparameters, CbdHyperparameters, EvidenceError, EvidenceOptions};
use crate::parametric::{calibrate_dh, DhCalibrationOptions};
use cbd_protocol::{JointKernelAxis, NominalModel};
use cbd_runtime::kinematics::forward_kinematics;

/// What is assumed before any pose is measured, in the model's length unit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StatedPrior {
    /// RMS position error the geometric group leaves (the non-geometric part CbD models).
    pub error: f64,
    /// Measurement noise per coordinate.
    pub noise: f64,
}

/// The stated prior as CbD's kernels: periodic b = 1 (Gaussian ℓ = 1 for prismatic joints) on every
/// joint, task width = the reach, and the expected squared error `error²` split evenly between the
/// joint field (γ_V mean |Dk0|²_F = error²/2) and the task field (m γ_W = error²/2) over `joints`.
pub fn stated(nominal: &NominalModel, joints: &[f64], reach: f64, prior: StatedPrior) -> CbdHyperparameters {
    let (n, m) = (nominal.n_joints(), nominal.task_dim());
    let count = (joints.len() / n.max(1)).max(1);
    let mean_j2 = joints
        .chunks_exact(n)
        .map(|q| {
            let k = forward_kinematics(nominal, q);
            (0..m).map(|c| (0..n).map(|d| k.jacobian[c][d].powi(2)).sum::<f64>()).sum::<f64>()
        })
        .sum::<f64>()
        / count as f64;
    let e2 = prior.error * prior.error;
    CbdHyperparameters {
        joint_axes: (0..n)
            .map(|d| if nominal.is_revolute(d) { JointKernelAxis::Periodic { b: 1.0 } } else { JointKernelAxis::Gaussian { width: 1.0 } })
            .collect(),
        joint_gamma: if mean_j2 > 0.0 { 0.5 * e2 / mean_j2 } else { 0.0 },
        task_width: reach,
        task_gamma: 0.5 * e2 / m as f64,
        sigma: prior.noise,
    }
}

/// CbD's evidence on what the DH fit of the geometric group leaves (the residual dh+cbd's CbD
/// models), read as measurements of the nominal: y − (k_dh(q) − k0(q)); the data as they are when
/// the DH fit fails.
pub fn from_measurements(nominal: &NominalModel, data: &Measurements) -> Result<CbdHyperparameters, EvidenceError> {
    let options = DhCalibrationOptions { planar_as_dh: true, ..DhCalibrationOptions::default() };
    let (n, m) = (data.n_joints, data.task_dim);
    let mut residual_data = data.clone();
    if let Ok(fit) = calibrate_dh(nominal, data, &options) {
        let fitted = crate::nominal::positions(&fit.model, &data.joints, m);
        for (i, q) in data.joints.chunks_exact(n).enumerate() {
            let k0 = forward_kinematics(nominal, q);
            for c in 0..m {
                residual_data.positions[i * m + c] -= fitted[i * m + c] - k0.position[c];
            }
        }
    }
    let norm = crate::evidence::normalisation_of(&residual_data);
    let evidence = choose_cbd_hyperparameters(nominal, &residual_data, &norm, &EvidenceOptions::default())?;
    Ok(evidence.hyperparameters)
}

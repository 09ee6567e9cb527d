//! The Gaussian process's hyperparameters for planning: CbD's own evidence on the poses measured so
//! far — and the geometry `cbd fit` would choose on them, the model the plan is for (the pipeline's
//! choice, `calibrate::geometry`) —, or before any data a stated prior for the calibrated geometry
//! (docs/DESIGN.md §13).

use crate::calibrate::{Geometry, GeometryChoice, Settings};
use crate::data::Measurements;
use crate::evidence::CbdHyperparameters;
use cbd_protocol::NominalModel;
use cbd_runtime::internals::kinematics::forward_kinematics;

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
        joint_axes: crate::axis_forms::default_axes(nominal),
        joint_gamma: if mean_j2 > 0.0 { 0.5 * e2 / mean_j2 } else { 0.0 },
        task_width: reach,
        task_gamma: 0.5 * e2 / m as f64,
        sigma: prior.noise,
        configuration: None,
    }
}

/// The hypothesis `cbd fit` chooses on the measured poses (`calibrate::geometry::choose_geometry`:
/// the nominal chain, or its geometric group calibrated first) and CbD's hyperparameters for it by
/// its evidence — for the calibrated geometry on what the DH fit leaves, read as measurements of the
/// nominal, y − (k_dh(q) − k0(q)), the residual the posterior's geometric basis starts from.
pub fn from_measurements(nominal: &NominalModel, data: &Measurements) -> crate::Result<(CbdHyperparameters, GeometryChoice)> {
    let settings = Settings { geometry: Geometry::Auto, ..Settings::default() };
    let data = crate::data::stage_rows::StageRows::new(data.clone(), &settings.cuts());
    let (hypothesis, choice, _) = crate::calibrate::geometry::choose_geometry(nominal, &data, &data.normalisation, &settings, false)?;
    Ok((hypothesis.hyperparameters, choice))
}

//! Compensation of many targets by a blob (the runtime's `Calibrator::compensate` and
//! `compensate_pose`), with the seeds a user gives or the hints the training data suggest: the
//! computation behind `cbd compensate` and the commanded tables of `cbd compare --commanded`.

use crate::error::Error;
use cbd_protocol::{Model, NominalModel};
use cbd_runtime::internals::inverse_kinematics::nominal_position;
use cbd_runtime::{CompensateOptions, Compensation};

/// Steps of the nominal inverse kinematics that makes the seed of every row.
const NOMINAL_IK_ITERATIONS: usize = 8;

/// One pose target's command and outcome.
pub struct PoseCommandRow {
    pub joints: Vec<f64>,
    pub compensation: cbd_runtime::PoseCompensation,
}

/// Hints tried per target pose without `--seeds`: the nearest training poses in turn, until one
/// is reached. The seed chooses the nominal inverse kinematics' branch (elbow, wrist, shoulder), and
/// the nearest training pose can sit on a branch that passes near a singularity for this target;
/// the next nearest usually does not (simulated arm, README: 4 hints reach 48 of 50 targets, 8 reach
/// 49). A bounded count keeps the cost per target bounded.
pub const POSE_HINTS: usize = 8;

/// Compensates every target pose (model units) with `Calibrator::compensate_pose` from `seeds`;
/// without seeds, from the training poses whose nominal tool points are nearest the target's
/// ([`nearest_training_poses`]), the first that reaches the target (else the smallest residual).
pub fn compensate_all_poses(
    blob: &[u8],
    targets: &[crate::nominal::Frame],
    seeds: Option<&[Vec<f64>]>,
) -> std::result::Result<Vec<PoseCommandRow>, CompensateError> {
    let model = cbd_protocol::decode(blob).map_err(|e| CompensateError::Model(e.into()))?;
    let n = model.n_joints();
    let hints: Vec<Vec<Vec<f64>>> = match seeds {
        Some(s) => s.iter().map(|q| vec![q.clone()]).collect(),
        None => targets.iter().map(|t| nearest_training_poses(&model, t, POSE_HINTS)).collect(),
    };
    let mut storage = vec![0.0; cbd_runtime::storage_len_for(&model)];
    let mut cal = cbd_runtime::Calibrator::from_model(model, &mut storage).map_err(|e| CompensateError::Model(e.into()))?;
    crate::predict::check_calibrator(&mut cal).map_err(|e| CompensateError::Model(e.into()))?;
    let mut out = Vec::with_capacity(targets.len());
    for (row, (target, hints)) in targets.iter().zip(&hints).enumerate() {
        let mut best: Option<PoseCommandRow> = None;
        for hint in hints {
            let mut joints = vec![0.0; n];
            let compensation = cal
                .compensate_pose(&target.translation(), &target.rotation(), hint, &mut joints)
                .map_err(|e| CompensateError::Row { row, message: e.to_string() })?;
            let worse = |b: &PoseCommandRow| {
                let cost = |c: &cbd_runtime::PoseCompensation| (c.position_residual, c.angle_residual);
                !(cost(&compensation).0 < cost(&b.compensation).0)
            };
            if !joints.iter().all(|v| v.is_finite()) || best.as_ref().is_some_and(worse) {
                continue;
            }
            let reached = compensation.reached;
            best = Some(PoseCommandRow { joints, compensation });
            if reached {
                break;
            }
        }
        let Some(best) = best else {
            return Err(CompensateError::Row {
                row,
                message: "the compensation is not finite: the model cannot be used at this target".into(),
            });
        };
        out.push(best);
    }
    Ok(out)
}

/// The `count` training poses (of the blob: configurations pose-major, one per tool point) whose
/// nominal tool points are nearest those of `target` (Σ_j |k0_j(q) − (R* p_j + t*)|²), nearest first.
pub fn nearest_training_poses(model: &Model<'_>, target: &crate::nominal::Frame, count: usize) -> Vec<Vec<f64>> {
    let m_p = model.nominal.tool_point_count().max(1);
    let wanted: Vec<[f64; 3]> = (0..m_p).map(|j| target.apply(model.nominal.tool_point(j).unwrap_or([0.0; 3]))).collect();
    nearest_training_configurations(model, count, |q| {
        (0..m_p)
            .map(|j| {
                let k0 = cbd_runtime::internals::kinematics::forward_kinematics_at(&model.nominal, q, j);
                (0..3).map(|c| (k0.position[c] - wanted[j][c]).powi(2)).sum::<f64>()
            })
            .sum()
    })
}

/// The training configuration (of the blob) whose nominal position is nearest `target`: the
/// default hint of the nominal inverse kinematics.
pub fn nearest_training_configuration(model: &Model<'_>, target: &[f64]) -> Vec<f64> {
    let mut nearest = nearest_training_configurations(model, 1, |q| {
        let k0 = cbd_runtime::internals::kinematics::forward_kinematics(&model.nominal, q);
        k0.position.iter().zip(target).map(|(a, b)| (a - b) * (a - b)).sum()
    });
    nearest.pop().unwrap_or_else(|| vec![0.0; model.n_joints()])
}

/// The `count` training poses (one configuration per pose: the blob's points are pose-major, one
/// per tool point) of smallest `distance`, nearest first (a stable sort: ties keep the data's
/// order); all zeros when the blob has none.
fn nearest_training_configurations(model: &Model<'_>, count: usize, distance: impl Fn(&[f64]) -> f64) -> Vec<Vec<f64>> {
    let n = model.n_joints().max(1);
    let points: Vec<f64> = model.points.iter().collect();
    let mut scored: Vec<(f64, &[f64])> =
        points.chunks_exact(n).step_by(model.nominal.tool_point_count().max(1)).map(|q| (distance(q), q)).collect();
    scored.sort_by(|a, b| a.0.total_cmp(&b.0));
    let nearest: Vec<Vec<f64>> = scored.iter().take(count).map(|(_, q)| q.to_vec()).collect();
    if nearest.is_empty() {
        vec![vec![0.0; n]]
    } else {
        nearest
    }
}

/// One row's result.
pub struct CommandRow {
    pub joints: Vec<f64>,
    pub compensation: Compensation,
}

/// Why [`compensate_all`] failed: the model (the blob's fault) or one target row (0-based in
/// `targets`; the caller names its file line).
#[derive(Debug, thiserror::Error)]
pub enum CompensateError {
    /// The blob does not decode, the runtime refuses it, or it is damaged.
    #[error("{0}")]
    Model(#[source] Error),
    #[error("row {row}: {message}")]
    Row { row: usize, message: String },
}

/// Compensates every target (model units): seed from `seeds` (or [`nearest_training_configuration`]),
/// nominal IK of the target from it ([`nominal_position`]), then `Calibrator::compensate_with`.
/// A blob whose model is unusable ([`crate::predict::check_calibrator`]) is refused before any
/// target, and a row whose command or residual is not finite is an error, never a NaN in the output.
pub fn compensate_all(
    blob: &[u8],
    targets: &[Vec<f64>],
    seeds: Option<&[Vec<f64>]>,
    iterations: usize,
    tolerance: Option<f64>,
) -> std::result::Result<Vec<CommandRow>, CompensateError> {
    let model = cbd_protocol::decode(blob).map_err(|e| CompensateError::Model(e.into()))?;
    let n = model.n_joints();
    let nominal: NominalModel = model.nominal.clone();
    let hints: Vec<Vec<f64>> = match seeds {
        Some(s) => s.to_vec(),
        None => targets.iter().map(|t| nearest_training_configuration(&model, t)).collect(),
    };
    let mut storage = vec![0.0; cbd_runtime::storage_len_for(&model)];
    let mut cal = cbd_runtime::Calibrator::from_model(model, &mut storage).map_err(|e| CompensateError::Model(e.into()))?;
    crate::predict::check_calibrator(&mut cal).map_err(|e| CompensateError::Model(e.into()))?;
    let mut options = CompensateOptions::for_model(&cal);
    options.iterations = iterations;
    if let Some(t) = tolerance {
        options.tolerance = t;
    }
    let scale = cal.model().normalisation.task_scale;
    let mut out = Vec::with_capacity(targets.len());
    for (row, (target, hint)) in targets.iter().zip(&hints).enumerate() {
        let at = |message: String| CompensateError::Row { row, message };
        let mut seed = vec![0.0; n];
        nominal_position(&nominal, target, hint, &mut seed, NOMINAL_IK_ITERATIONS, scale)
            .ok_or_else(|| at("the nominal inverse kinematics failed (target or seed not finite)".into()))?;
        let mut joints = vec![0.0; n];
        let compensation = cal.compensate_with(target, &seed, &mut joints, &options).map_err(|e| at(e.to_string()))?;
        if !(compensation.residual.is_finite() && joints.iter().all(|v| v.is_finite())) {
            return Err(at(format!(
                "the compensation is not finite (residual {:e}): the model cannot be used at this target",
                compensation.residual
            )));
        }
        out.push(CommandRow { joints, compensation });
    }
    Ok(out)
}

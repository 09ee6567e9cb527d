//! The contract of a written command (`cbd compensate`): a row flagged `ok` is finite, inside the
//! joint limits, reaches its target within the model's precision and has a determined
//! orientation. Checked where the row is written, on the command as written: the controller's
//! values re-read as the import reads them (`data::joint_columns`), the blob evaluated there. The
//! runtime's own verdict is not taken on trust — the mapping back to the controller's values, a
//! turn into the limits and the rounding of the printed digits all come after it.

use crate::error::Error;
use crate::nominal::Frame;
use cbd_protocol::Model;
use cbd_runtime::{CompensateOptions, PoseCompensateOptions};

/// What is wrong with one written row (none: `ok`).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct RowFlags {
    pub not_reached: bool,
    pub outside_limits: bool,
    pub degenerate_target: bool,
    pub singular: bool,
    pub extrapolating: bool,
}

impl RowFlags {
    /// The flags column: `ok`, or what is wrong joined by `+`.
    pub fn text(&self) -> String {
        let named = [
            (self.not_reached, "not_reached"),
            (self.outside_limits, "outside_limits"),
            (self.degenerate_target, "degenerate_target"),
            (self.singular, "singular"),
            (self.extrapolating, "extrapolating"),
        ];
        let set: Vec<&str> = named.iter().filter(|(on, _)| *on).map(|(_, name)| *name).collect();
        if set.is_empty() {
            "ok".into()
        } else {
            set.join("+")
        }
    }

    pub fn is_ok(&self) -> bool {
        self.text() == "ok"
    }
}

/// Per joint: whether the calibrated model repeats after a whole turn of it — a revolute joint
/// with a periodic kernel axis and no encoder scale (δ = scale · q is not periodic). Only such a
/// joint's command may be turned into the limits.
pub fn periodic_joints(model: &Model<'_>) -> Vec<bool> {
    let scaled =
        |d: usize| model.nominal.effects().list.iter().map(crate::effects::Instance::of).any(|e| !e.kind.periodic() && e.site.index == d);
    (0..model.n_joints())
        .map(|d| {
            model.nominal.is_revolute(d)
                && model.joint_kernel.axes.get(d).is_some_and(|a| crate::axis_forms::form_of(a).periodic())
                && !scaled(d)
        })
        .collect()
}

/// A position command checked: |k1(q) − target| at the re-read joints `q` and whether that is
/// within the tolerance (`tolerance`, model units, or the runtime's default for the model).
pub struct PositionCheck {
    pub residual: f64,
    pub reached: bool,
    /// The tolerance `reached` was judged with (model units).
    pub tolerance: f64,
}

/// Checks every re-read command `joints[i]` (model units) against `targets[i]`.
pub fn check_positions(
    blob: &[u8],
    joints: &[Vec<f64>],
    targets: &[Vec<f64>],
    tolerance: Option<f64>,
) -> Result<Vec<PositionCheck>, Error> {
    let model = cbd_protocol::decode(blob)?;
    let mut storage = vec![0.0; cbd_runtime::storage_len_for(&model)];
    let mut cal = cbd_runtime::Calibrator::from_model(model, &mut storage)?;
    let tolerance = tolerance.unwrap_or(CompensateOptions::for_model(&cal).tolerance);
    let mut out = Vec::with_capacity(joints.len());
    for (q, target) in joints.iter().zip(targets) {
        let residual = match cal.evaluate(q) {
            Ok(e) => e.position().iter().zip(target).map(|(a, b)| (a - b) * (a - b)).sum::<f64>().sqrt(),
            Err(_) => f64::INFINITY,
        };
        out.push(PositionCheck { residual, reached: residual <= tolerance, tolerance });
    }
    Ok(out)
}

/// A pose command checked at the re-read joints: the calibrated tool frame's origin and angle
/// from the target frame, and whether both are within the runtime's tolerances
/// (`PoseCompensateOptions::for_model`).
pub struct PoseCheck {
    pub position_residual: f64,
    pub angle_residual: f64,
    pub reached: bool,
}

/// Checks every re-read command `joints[i]` (model units) against the target frame `targets[i]`.
pub fn check_poses(blob: &[u8], joints: &[Vec<f64>], targets: &[Frame]) -> Result<Vec<PoseCheck>, Error> {
    let model = cbd_protocol::decode(blob)?;
    let mut storage = vec![0.0; cbd_runtime::storage_len_for(&model)];
    let mut cal = cbd_runtime::Calibrator::from_model(model, &mut storage)?;
    let options = PoseCompensateOptions::for_model(&cal);
    let mut out = Vec::with_capacity(joints.len());
    for (q, target) in joints.iter().zip(targets) {
        let (position_residual, angle_residual) = match cal.evaluate_pose(q) {
            Ok(pose) => {
                let reached = Frame::new(pose.rotation(), pose.origin());
                let offset = crate::nominal::norm(crate::nominal::sub(reached.translation(), target.translation()));
                (offset, crate::nominal::tool_points::rotation_angle(&reached, target))
            }
            Err(_) => (f64::INFINITY, f64::INFINITY),
        };
        let reached = position_residual <= options.position_tolerance && angle_residual <= options.angle_tolerance;
        out.push(PoseCheck { position_residual, angle_residual, reached });
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn flags_name_every_fault_and_ok_only_without_one() {
        assert_eq!(RowFlags::default().text(), "ok");
        let f = RowFlags { not_reached: true, outside_limits: true, extrapolating: true, ..RowFlags::default() };
        assert_eq!(f.text(), "not_reached+outside_limits+extrapolating");
        assert!(!f.is_ok() && RowFlags::default().is_ok());
        assert_eq!(RowFlags { degenerate_target: true, ..RowFlags::default() }.text(), "degenerate_target");
    }
}

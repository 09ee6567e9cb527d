//! Joint commands that put the calibrated arm's tool at Cartesian targets, in the blob's own units
//! (the runtime's `Calibrator::compensate` from the nominal model's inverse kinematics), each with
//! the flags `cbd compensate` writes.

use crate::evaluation::command_check::{check_positions, RowFlags};
use crate::evaluation::compensation::{compensate_all, CompensateError};

/// Most Gauss–Newton steps a compensation takes (`cbd compensate --iterations`; the Python package's `iterations`).
pub const MAX_ITERATIONS: usize = 64;

/// One target's command (model units: radians, the model's length unit) and what is wrong with it.
pub struct CompensatedCommand {
    pub joints: Vec<f64>,
    /// `ok`, or `not_reached`, `outside_limits` (a value not finite: a blob alone knows no joint
    /// limits), `singular`, `extrapolating` joined by `+`; `ok` only when the command reaches its
    /// target at the runtime's tolerance.
    pub flags: String,
}

/// Commands for `targets` (model units) from `seeds` (or the nearest training configuration's),
/// with `iterations` Gauss–Newton steps, each checked as `cbd compensate` checks its rows.
pub fn compensate(
    blob: &[u8],
    targets: &[Vec<f64>],
    seeds: Option<&[Vec<f64>]>,
    iterations: usize,
) -> Result<Vec<CompensatedCommand>, CompensateError> {
    let rows = compensate_all(blob, targets, seeds, iterations, None)?;
    let returned: Vec<Vec<f64>> = rows.iter().map(|r| r.joints.clone()).collect();
    let checks = check_positions(blob, &returned, targets, None).map_err(CompensateError::Model)?;
    Ok(rows
        .into_iter()
        .zip(&checks)
        .map(|(r, check)| {
            let flags = RowFlags {
                not_reached: !check.reached,
                outside_limits: r.joints.iter().any(|v| !v.is_finite()),
                singular: r.compensation.singular,
                extrapolating: r.compensation.extrapolating,
                ..Default::default()
            };
            CompensatedCommand { flags: flags.text(), joints: r.joints }
        })
        .collect())
}

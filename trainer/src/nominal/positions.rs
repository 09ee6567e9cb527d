//! Batched nominal forward kinematics: k0(x_i) for every row of a joint matrix.

use cbd_protocol::NominalModel;
use cbd_runtime::internals::kinematics::{forward_kinematics_at, Kinematics};

/// The first `m` coordinates of `model`'s tool position at every row of `joints` (row-major,
/// `model.n_joints()` per row), by the runtime's forward kinematics (effects included); with
/// several tool points, row r's is tool point r mod m_p ([`row_kinematics`]).
pub fn positions(model: &NominalModel, joints: &[f64], m: usize) -> Vec<f64> {
    joints.chunks_exact(model.n_joints()).enumerate().flat_map(|(r, q)| row_kinematics(model, q, r).position.into_iter().take(m)).collect()
}

/// k0 and Dk0 of data row `row` at joints `x`: tool point `row` mod m_p of `model` (pose-major
/// rows, `data::Measurements`); a model without tool points gives the runtime's
/// `forward_kinematics` bit for bit.
pub fn row_kinematics(model: &NominalModel, x: &[f64], row: usize) -> Kinematics {
    forward_kinematics_at(model, x, row % model.tool_point_count())
}

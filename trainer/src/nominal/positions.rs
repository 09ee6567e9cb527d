//! Batched nominal forward kinematics: k0(x_i) for every row of a joint matrix.

use cbd_protocol::NominalModel;
use cbd_runtime::kinematics::forward_kinematics;

/// The first `m` coordinates of `model`'s tool position at every row of `joints` (row-major,
/// `model.n_joints()` per row), by the runtime's forward kinematics (effects included).
pub fn positions(model: &NominalModel, joints: &[f64], m: usize) -> Vec<f64> {
    joints.chunks_exact(model.n_joints()).flat_map(|q| forward_kinematics(model, q).position.into_iter().take(m)).collect()
}

//! The augmented nominal kinematics k0_aug(q) = k_rigid(q + δ(q)) + b(q) and the response of one
//! effect, as the diagnosis needs them: evaluated by the runtime (`cbd_runtime::internals::kinematics::augmented`), so that
//! the diagnosis, the CbD fit on top of it and the controller all use one implementation. (The
//! simulator's independent implementation, `simulate::effects`, only makes test data.)

use cbd_protocol::NominalModel;
use cbd_runtime::internals::kinematics::augmented::{effect_terms, Order};
use cbd_runtime::internals::kinematics::tool_point::forward_kinematics_at;

/// What one effect adds at q, with its own parameter values: to δ (joint) or to b (task)
/// (each kind's `effects::EffectKind::response`).
pub use crate::effects::Response;

/// k0_aug(q) at tool point `point` (0 for a model without tool points), the first `m`
/// coordinates (the data's: 2 for a planar arm's DH form). Data row r measures tool point
/// r mod m_p ([`point_of_row`]).
pub fn position(model: &NominalModel, q: &[f64], m: usize, point: usize) -> Vec<f64> {
    forward_kinematics_at(model, q, point).position[..m].to_vec()
}

/// The tool point data row `row` measures: row mod m_p (pose-major rows, `data::Measurements`).
pub fn point_of_row(model: &NominalModel, row: usize) -> usize {
    row % model.tool_point_count().max(1)
}

/// The model without its effects (same geometry and gravity model).
pub fn rigid(model: &NominalModel) -> NominalModel {
    let mut r = model.clone();
    r.effects_mut().list.clear();
    r
}

/// Dk_rigid(q + δ(q)) of tool point `point` (row-major task_dim × n), the derivative through which
/// a joint deflection moves that point: δ deflects the chain, every point rides on the deflected
/// flange (δ and b do not depend on the tool). `rigid` is [`rigid`]`(model)`.
pub fn deflected_rigid_jacobian(model: &NominalModel, rigid: &NominalModel, q: &[f64], point: usize) -> Vec<f64> {
    let n = q.len();
    let delta = effect_terms(model, &model.effects().list, q, Order::Value).delta;
    let moved: Vec<f64> = q.iter().zip(&delta).map(|(a, b)| a + b).collect();
    let k = forward_kinematics_at(rigid, &moved, point);
    (0..model.task_dim()).flat_map(|c| k.jacobian[c][..n].to_vec()).collect()
}

/// Gravity torque τ_j(q) of the nominal chain under its mass model.
pub fn gravity_torques(model: &NominalModel, q: &[f64]) -> Vec<f64> {
    cbd_runtime::internals::kinematics::augmented::gravity_torques(model, q).iter().copied().take(q.len()).collect()
}

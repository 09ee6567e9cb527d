//! The augmented nominal kinematics k0_aug(q) = k_rigid(q + δ(q)) + b(q) (h4-common.md) and the
//! response of one effect, as the diagnosis needs them: the one place that evaluates effects.
//! INTERIM (until the runtime's `cbd_runtime::effects` exists): evaluated with the simulator's
//! independent implementation.

use crate::simulate::effects::{gravity_torques_numerical, EffectArm, InjectedEffect};
use cbd_protocol::{Effect, NominalModel};
use cbd_runtime::nominal::forward_kinematics;

/// What one effect adds at q, with its own parameter values: to δ (joint) or to b (task).
#[derive(Debug, Clone, PartialEq)]
pub enum Response {
    Joint(Vec<f64>),
    Task([f64; 3]),
}

fn injected(e: &Effect) -> InjectedEffect {
    match *e {
        Effect::EncoderScale { joint, scale } => InjectedEffect::EncoderScale { joint: joint as usize, scale },
        Effect::Transmission { joint, harmonic, cos, sin } => {
            InjectedEffect::Transmission { joint: joint as usize, harmonic: harmonic as u32, cos, sin }
        }
        Effect::GravityCompliance { joint, compliance } => InjectedEffect::GravityCompliance { joint: joint as usize, compliance },
        Effect::LinkBending { link, compliance } => InjectedEffect::LinkBending { link: link as usize, compliance },
    }
}

fn arm(model: &NominalModel) -> EffectArm {
    let mut a = EffectArm::new(model.clone());
    a.effects = model.effects().list.iter().map(injected).collect();
    a
}

/// k0_aug(q), the first `task_dim` coordinates.
pub fn position(model: &NominalModel, q: &[f64]) -> Vec<f64> {
    arm(model).position(q, 0)
}

/// The model without its effects (same geometry and gravity model).
pub fn rigid(model: &NominalModel) -> NominalModel {
    let mut r = model.clone();
    r.effects_mut().list.clear();
    r
}

/// Dk_rigid(q + δ(q)) (row-major task_dim × n), the derivative through which a joint deflection
/// moves the tool. `rigid` is [`rigid`]`(model)`.
pub fn deflected_rigid_jacobian(model: &NominalModel, rigid: &NominalModel, q: &[f64]) -> Vec<f64> {
    let n = q.len();
    let d = arm(model).deflection(q);
    let moved: Vec<f64> = q.iter().zip(&d).map(|(a, b)| a + b).collect();
    let k = forward_kinematics(rigid, &moved);
    (0..model.task_dim()).flat_map(|c| k.jacobian[c][..n].to_vec()).collect()
}

/// The contribution of `effect` at q (its own parameter values).
pub fn response(model: &NominalModel, effect: &Effect, q: &[f64]) -> Response {
    let mut a = EffectArm::new(model.clone());
    a.effects = vec![injected(effect)];
    match effect {
        Effect::LinkBending { .. } => {
            let r = rigid(model);
            let p0 = forward_kinematics(&r, q).position;
            let p = a.position(q, 0);
            let mut b = [0.0; 3];
            for (c, v) in p.iter().enumerate() {
                b[c] = v - p0[c];
            }
            Response::Task(b)
        }
        _ => Response::Joint(a.deflection(q)),
    }
}

/// Gravity torque τ_j(q) of the nominal chain under its mass model.
pub fn gravity_torques(model: &NominalModel, q: &[f64]) -> Vec<f64> {
    gravity_torques_numerical(&rigid(model), &model.effects().gravity, q)
}

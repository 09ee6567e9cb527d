//! Helpers shared by the diagnose test files.

use rand::{Rng, SeedableRng};

/// Geometric errors of a real six-joint arm drawn from `seed`, in the order of
/// `nominal::dh_parameters::parameter_names(6)`: ±0.05° for angles, ±0.5 mm for lengths.
pub fn six_joint_geometric_errors(seed: u64) -> Vec<f64> {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let deg = std::f64::consts::PI / 180.0;
    cbd_trainer::nominal::dh_parameters::parameter_names(6)
        .iter()
        .map(|s| {
            if s.starts_with("alpha") || s.starts_with("theta") || s.starts_with("base_r") {
                rng.gen_range(-0.05..0.05) * deg
            } else {
                rng.gen_range(-0.5..0.5)
            }
        })
        .collect()
}

/// Relative RMS gap between the diagnosed gravity deflection of `joint` (the diagnosed model's
/// gravity effects on that joint, evaluated by the runtime) and the simulated arm's, over
/// `joints` (row-major): ‖δ_fit − δ_true‖ / ‖δ_true‖. Compares curves, not moments: individual
/// moments may be unidentifiable while their deflection is.
pub fn gravity_deflection_gap(
    d: &cbd_trainer::diagnose::Diagnosis,
    arm: &cbd_trainer::simulate::effects::EffectArm,
    joint: usize,
    joints: &[f64],
) -> f64 {
    use cbd_protocol::Effect;
    let model = &d.model_after;
    let n = model.n_joints();
    let gravity: Vec<Effect> = model
        .effects()
        .list
        .iter()
        .copied()
        .filter(|e| match *e {
            Effect::GravityMoment { joint: j, .. } | Effect::GravityCompliance { joint: j, .. } => j as usize == joint,
            _ => false,
        })
        .collect();
    let (mut gap, mut size) = (0.0, 0.0);
    for q in joints.chunks_exact(n) {
        let fit = cbd_runtime::internals::kinematics::augmented::effect_terms(
            model,
            &gravity,
            q,
            cbd_runtime::internals::kinematics::augmented::Order::Value,
        )
        .delta[joint];
        let truth = arm.deflection(q)[joint];
        gap += (fit - truth).powi(2);
        size += truth.powi(2);
    }
    (gap / size).sqrt()
}

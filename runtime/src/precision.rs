//! The model's own precision (issue 25): a bound on how far rounding alone can move one evaluation
//! of k1, in the user's length unit. Compensation counts a target reached within it (never tighter
//! than its fixed 1e-9 of the task scale): a model whose terms cancel cannot resolve less, and a
//! well-conditioned one resolves far less.
//!
//! Every evaluated position is k0 plus a sum of terms; rounding moves it by at most a few unit
//! roundoffs of the largest magnitudes summed, R + T: R the nominal positions' radius, T a bound on
//! Σ |term| — for the kernel form Σ_j |P_j| (1 + |γ| J²) (K_W ≤ 1, |K_V| ≤ |γ|, |Dk0| ≤ J; with the
//! configuration term, docs/DESIGN.md §16, + γ_C: c_j K_X ≤ γ_C), for the expansion the stages'
//! Σ_f |c_f| J + Σ_g |d_g| (|φ_f| ≤ 1, |ψ_g| ≤ 1) times their step.
//! Internal units throughout, scaled by the task scale at the end.

use crate::kinematics::{forward_kinematics, with_tool_point};
use crate::real::Real;
use cbd_protocol::{Model, MAX_JOINTS};

/// Unit roundoffs allowed per evaluation: the flow's sums and products, the integrator's stages.
const ROUNDING_STEPS: f64 = 16.0;

/// The bound for `model`, user units; one nominal evaluation per measured configuration (at load).
pub fn evaluation_precision(model: &Model<'_>) -> f64 {
    let (n, m) = (model.n_joints(), model.task_dim());
    let (mut radius, mut jac_max) = (0.0f64, 0.0f64);
    let mut x = [0.0; MAX_JOINTS];
    for i in 0..model.n_points as usize {
        for (d, xd) in x.iter_mut().enumerate().take(n) {
            *xd = model.points.get(i * n + d).unwrap_or(0.0);
        }
        // Control point i is tool point i % m_p (one point: the model itself, no copy).
        let m_p = model.nominal.tool_point_count();
        let Some(k0) = with_tool_point(&model.nominal, i % m_p.max(1), |nominal| forward_kinematics(nominal, x.get(..n).unwrap_or(&[])))
        else {
            continue;
        };
        let k0 = k0.normalised(&model.normalisation);
        let r2: f64 = k0.position.iter().take(m).map(|v| v * v).sum();
        let j2: f64 = k0.jacobian.iter().take(m).flat_map(|row| row.iter().take(n)).map(|v| v * v).sum();
        radius = radius.max(libm::sqrt(r2));
        jac_max = jac_max.max(libm::sqrt(j2));
    }
    let terms = match &model.expansion {
        None => {
            let gamma = libm::fabs(model.joint_kernel.gamma);
            let sum = model.momenta.iter().map(libm::fabs).sum::<f64>();
            match &model.configuration_kernel {
                None => sum * (1.0 + gamma * jac_max * jac_max),
                // The configuration term's c_j K_X ≤ γ_C (§16).
                Some(c) => sum * (1.0 + gamma * jac_max * jac_max + c.gamma),
            }
        }
        Some(e) => {
            let stages = model.integrator.stage_count().max(1);
            let joint = e.n_joint_features as usize * n;
            let per_stage = joint + e.n_task_features as usize * m;
            let mut sum = 0.0;
            for (k, w) in e.weights.iter().enumerate() {
                let weight = if per_stage > 0 && k % per_stage < joint { jac_max } else { 1.0 };
                sum += libm::fabs(w) * weight;
            }
            // Each stage's field moves the state by its step: 1/steps of the stages' average.
            sum / stages as f64
        }
    };
    ROUNDING_STEPS * unit_roundoff() * model.normalisation.task_scale * (radius + terms)
}

/// Half the machine epsilon of [`Real`].
// A cast from f64 to f64 in the default build, from f32 with the feature `f32`.
#[allow(clippy::unnecessary_cast)]
pub fn unit_roundoff() -> f64 {
    0.5 * Real::EPSILON as f64
}

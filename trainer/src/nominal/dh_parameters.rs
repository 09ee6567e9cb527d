//! A DH chain's parameters as one vector — per joint a, α, d, θ offset; the base's translation and
//! rotation vector; the tool's translation — shared by DH calibration, diagnosis and the simulators.

use super::{rotation_about, Frame};
use cbd_protocol::DhChain;

/// Number of parameters for `n` joints: 4 per joint, 6 base, 3 tool.
pub fn parameter_count(n: usize) -> usize {
    4 * n + 9
}

/// Parameter names, in the order of the parameter vector (and of `DhFitStats::parameter_changes`).
pub fn parameter_names(n: usize) -> Vec<String> {
    let mut names = Vec::with_capacity(parameter_count(n));
    for i in 1..=n {
        for p in ["a", "alpha", "d", "theta_offset"] {
            names.push(format!("{p}{i}"));
        }
    }
    for p in ["base_tx", "base_ty", "base_tz", "base_rx", "base_ry", "base_rz", "tool_tx", "tool_ty", "tool_tz"] {
        names.push(p.to_string());
    }
    names
}

/// The chain with parameter changes `p` applied to `nominal`.
pub fn apply_parameters(nominal: &DhChain, p: &[f64]) -> DhChain {
    let mut c = nominal.clone();
    let n = c.joints.len();
    for (i, j) in c.joints.iter_mut().enumerate() {
        j.a += p[4 * i];
        j.alpha += p[4 * i + 1];
        j.d += p[4 * i + 2];
        j.theta_offset += p[4 * i + 3];
    }
    let o = 4 * n;
    let r = [p[o + 3], p[o + 4], p[o + 5]];
    let angle = (r[0] * r[0] + r[1] * r[1] + r[2] * r[2]).sqrt();
    let rot = if angle > 0.0 { rotation_about([r[0] / angle, r[1] / angle, r[2] / angle], angle) } else { Frame::IDENTITY };
    let translation = std::array::from_fn(|k| nominal.base.translation[k] + p[o + k]);
    for k in 0..3 {
        c.tool.translation[k] += p[o + 6 + k];
    }
    // Base rotation turns about the base origin: rot ∘ base, then restore/shift the translation.
    c.base = rot.compose(&Frame::from_transform(&nominal.base)).with_translation(translation).to_transform();
    c
}

//! A DH chain's parameters as one vector — per joint a, α, d, θ offset; the base's translation and
//! rotation vector; the tool's translation; for a chain with tool points off the tool origin, the
//! tool's rotation vector too — shared by DH calibration, diagnosis and the simulators.

use super::{rotation_about, Frame};
use cbd_protocol::DhChain;

/// Number of parameters for `n` joints: 4 per joint, 6 base, 3 tool.
pub fn parameter_count(n: usize) -> usize {
    4 * n + 9
}

/// Number of parameters of `chain`: [`parameter_count`], plus the tool's rotation (3) when a tool
/// point lies off the tool origin. At the origin the tool's rotation moves no measured point, so
/// it is not a parameter there (a zero column would only add noise to the fit's factorisations).
pub fn parameter_count_for(chain: &DhChain) -> usize {
    parameter_count(chain.joints.len()) + if has_tool_rotation(chain) { 3 } else { 0 }
}

/// Whether `chain`'s parameter vector carries the tool's rotation: a tool point off the origin.
pub fn has_tool_rotation(chain: &DhChain) -> bool {
    chain.tool_points.iter().any(|p| p.iter().any(|v| *v != 0.0))
}

/// [`parameter_names`] of `chain`'s parameter vector ([`parameter_count_for`] entries).
pub fn parameter_names_for(chain: &DhChain) -> Vec<String> {
    let mut names = parameter_names(chain.joints.len());
    if has_tool_rotation(chain) {
        names.extend(["tool_rx", "tool_ry", "tool_rz"].map(String::from));
    }
    names
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

/// The chain with parameter changes `p` applied to `nominal`: [`parameter_count`] entries, or
/// [`parameter_count_for`] with the tool's rotation vector last (a rotation of the tool frame about
/// its own origin, in its own axes: R_tool ← R_tool Rot(r)).
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
    let rot = rotation_of_vector([p[o + 3], p[o + 4], p[o + 5]]);
    let translation = std::array::from_fn(|k| nominal.base.translation[k] + p[o + k]);
    for k in 0..3 {
        c.tool.translation[k] += p[o + 6 + k];
    }
    if p.len() >= o + 12 {
        let turned = Frame::from_transform(&nominal.tool).compose(&rotation_of_vector([p[o + 9], p[o + 10], p[o + 11]]));
        c.tool.rotation = turned.to_transform().rotation;
    }
    // Base rotation turns about the base origin: rot ∘ base, then restore/shift the translation.
    c.base = rot.compose(&Frame::from_transform(&nominal.base)).with_translation(translation).to_transform();
    c
}

/// The rotation of axis-angle vector `r` (radians); identity for r = 0.
fn rotation_of_vector(r: [f64; 3]) -> Frame {
    let angle = (r[0] * r[0] + r[1] * r[1] + r[2] * r[2]).sqrt();
    if angle > 0.0 {
        rotation_about([r[0] / angle, r[1] / angle, r[2] / angle], angle)
    } else {
        Frame::IDENTITY
    }
}

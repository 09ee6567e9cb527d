//! One link's share of a compliant joint's gravity deflection (docs/DESIGN.md §7):
//! δ_j += ∂/∂q_j g·(mass·o_k(q) + R_k(q)·first_moment), k = link ≥ j, in the gauge c_j = 1. Written
//! as `[[gravity.link_moments]]` (`data::effects_section`), not as an `[[effects]]` entry; the
//! library's "gravity compliance" group of joint j is its regressor over the links k ≥ j.

use super::{EffectKind, Injected, Instance, LibraryGroup, LibraryOptions, SimulatedArm, Site};
use cbd_protocol::{Effect, NominalModel};

pub struct GravityMoment;

/// The descriptor, as `effects::KINDS` lists it.
pub const KIND: super::Kind = super::Kind(&GravityMoment);

impl EffectKind for GravityMoment {
    fn name(&self) -> &'static str {
        "gravity_moment"
    }
    fn components(&self) -> &'static [&'static str] {
        &["mass", "first_moment_x", "first_moment_y", "first_moment_z"]
    }
    fn from_blob(&self, effect: &Effect) -> Option<Instance> {
        let Effect::GravityMoment { joint, link, mass, first_moment } = *effect else { return None };
        let [x, y, z] = first_moment;
        Some(Instance { kind: KIND, site: Site { index: joint as usize, sub: link as usize }, values: vec![mass, x, y, z] })
    }
    fn to_blob(&self, e: &Instance) -> Option<Effect> {
        let v = &e.values;
        Some(Effect::GravityMoment { joint: e.site.index as u8, link: e.site.sub as u8, mass: v[0], first_moment: [v[1], v[2], v[3]] })
    }
    fn inject(&self, e: &Instance, arm: &dyn SimulatedArm, q: &[f64]) -> Injected {
        let v = &e.values;
        Injected::Joint(e.site.index, arm.moment_torque(q, e.site.index, e.site.sub, v[0], [v[1], v[2], v[3]]))
    }
    /// Compliant joint j's gravity regressor: c_j·m_k and c_j·s_k for every link k ≥ j (in-plane
    /// data: the first moment's z component does nothing and is left out). Which combinations the
    /// data identify is decided on the Jacobian (`diagnose::usable_columns`).
    fn groups(&self, model: &NominalModel, _options: &LibraryOptions, m: usize, j: usize) -> Vec<LibraryGroup> {
        let components = if m < 3 { 3 } else { 4 };
        let params = (j..model.n_joints()).flat_map(|link| (0..components).map(move |c| (Site { index: j, sub: link }, c))).collect();
        vec![LibraryGroup {
            name: format!("gravity compliance q{}", j + 1),
            type_name: "gravity_compliance",
            harmonic: None,
            joint: j,
            params,
        }]
    }
    fn param_name(&self, site: Site, component: usize) -> String {
        match component {
            0 => format!("q{} link {} mass", site.index + 1, site.sub + 1),
            c => format!("q{} link {} first moment {}", site.index + 1, site.sub + 1, ["x", "y", "z"][(c - 1).min(2)]),
        }
    }
    /// Products c_j·m_k, c_j·s_k in the gauge c_j = 1 (angle or length unit per mass·length).
    fn unit(&self, model: &NominalModel, site: Site, component: usize, length: &str, _angle: &str) -> (String, bool) {
        let unit = if component == 0 { "mass".to_string() } else { format!("mass·{length}") };
        (unit, model.is_revolute(site.index))
    }
    fn regressor(&self) -> bool {
        true
    }
}

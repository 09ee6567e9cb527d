//! Compliance under gravity (point-mass model): δ_j = compliance · τ_j(q), τ_j the gravity torque
//! (force, for a prismatic joint) of `[gravity] link_masses`. The library fits a compliant joint
//! through its gravity regressor instead (`gravity_moment`).

use super::{EffectKind, EffectSpecError, FieldError, FieldType, Fields, FileUnits, Injected, Instance};
use super::{SimulatedArm, Site, Spec};
use cbd_protocol::{Effect, NominalModel};

pub struct GravityCompliance;

/// The descriptor, as `effects::KINDS` lists it.
pub const KIND: super::Kind = super::Kind(&GravityCompliance);

impl EffectKind for GravityCompliance {
    fn name(&self) -> &'static str {
        "gravity_compliance"
    }
    fn components(&self) -> &'static [&'static str] {
        &["compliance"]
    }
    fn from_blob(&self, effect: &Effect) -> Option<Instance> {
        let Effect::GravityCompliance { joint, compliance } = *effect else { return None };
        Some(Instance { kind: KIND, site: Site::at(joint as usize), values: vec![compliance] })
    }
    fn to_blob(&self, e: &Instance) -> Option<Effect> {
        Some(Effect::GravityCompliance { joint: e.site.index as u8, compliance: e.values[0] })
    }
    fn file_fields(&self) -> &'static [(&'static str, FieldType)] {
        &[("joint", FieldType::Index), ("compliance", FieldType::Number)]
    }
    fn read(&self, f: &Fields, units: &FileUnits) -> Result<Instance, FieldError> {
        let compliance = f.number("compliance");
        f.check(&[("compliance", compliance)])?;
        let joint = f.index("joint")?;
        // A revolute joint deflects by an angle, a prismatic one by a length.
        Ok(Instance { kind: KIND, site: Site::at(joint), values: vec![compliance * units.joint_unit(joint)] })
    }
    fn write(&self, e: &Instance, units: &FileUnits) -> String {
        format!("joint = {}\ncompliance = {:?}\n", e.site.index + 1, e.values[0] / units.joint_unit(e.site.index))
    }
    fn parse_spec(&self, s: &Spec) -> Option<Result<Instance, EffectSpecError>> {
        Some((|| {
            let joint = s.index("joint")?;
            Ok(Instance { kind: KIND, site: Site::at(joint), values: vec![s.number("compliance", None)?] })
        })())
    }
    fn inject(&self, e: &Instance, arm: &dyn SimulatedArm, q: &[f64]) -> Injected {
        Injected::Joint(e.site.index, e.values[0] * arm.gravity_torques(q)[e.site.index])
    }
    fn param_name(&self, site: Site, _component: usize) -> String {
        format!("compliance q{}", site.index + 1)
    }
    fn unit(&self, model: &NominalModel, site: Site, _component: usize, length: &str, angle: &str) -> (String, bool) {
        if model.is_revolute(site.index) {
            (format!("{angle}/(mass·{length})"), true)
        } else {
            (format!("{length}/(mass·{length})"), false)
        }
    }
}

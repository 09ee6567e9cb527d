//! Encoder (or gear-ratio) scale error: δ_j = scale · q_j. Not periodic in its joint.

use super::{EffectKind, EffectSpecError, EffectValueError, FieldError, FieldType, Fields, FileUnits, Injected, Instance};
use super::{LibraryGroup, LibraryOptions, SimulatedArm, Site, Spec};
use cbd_protocol::{Effect, NominalModel};

pub struct EncoderScale;

/// The descriptor, as `effects::KINDS` lists it.
pub const KIND: super::Kind = super::Kind(&EncoderScale);

/// An encoder scale error δ = scale·q: a relative error of 100 % or more is not an encoder's scale
/// error (it reverses or doubles every angle) but a wrong value or unit.
pub fn check_encoder_scale(scale: f64) -> Result<(), EffectValueError> {
    super::check_effect_value("scale", scale)?;
    if scale.abs() >= 1.0 {
        return Err(EffectValueError::EncoderScale { scale });
    }
    Ok(())
}

impl EffectKind for EncoderScale {
    fn name(&self) -> &'static str {
        "encoder_scale"
    }
    fn components(&self) -> &'static [&'static str] {
        &["scale"]
    }
    fn from_blob(&self, effect: &Effect) -> Option<Instance> {
        let Effect::EncoderScale { joint, scale } = *effect else { return None };
        Some(Instance { kind: KIND, site: Site::at(joint as usize), values: vec![scale] })
    }
    fn to_blob(&self, e: &Instance) -> Option<Effect> {
        Some(Effect::EncoderScale { joint: e.site.index as u8, scale: e.values[0] })
    }
    fn file_fields(&self) -> &'static [(&'static str, FieldType)] {
        &[("joint", FieldType::Index), ("scale", FieldType::Number)]
    }
    fn read(&self, f: &Fields, _units: &FileUnits) -> Result<Instance, FieldError> {
        let scale = f.number("scale");
        check_encoder_scale(scale).map_err(|e| f.error(e.to_string()))?;
        Ok(Instance { kind: KIND, site: Site::at(f.index("joint")?), values: vec![scale] })
    }
    fn write(&self, e: &Instance, _units: &FileUnits) -> String {
        format!("joint = {}\nscale = {:?}\n", e.site.index + 1, e.values[0])
    }
    fn parse_spec(&self, s: &Spec) -> Option<Result<Instance, EffectSpecError>> {
        Some((|| {
            let scale = s.number("scale", None)?;
            check_encoder_scale(scale).map_err(|e| s.bad(e.to_string()))?;
            Ok(Instance { kind: KIND, site: Site::at(s.index("joint")?), values: vec![scale] })
        })())
    }
    fn inject(&self, e: &Instance, _arm: &dyn SimulatedArm, q: &[f64]) -> Injected {
        Injected::Joint(e.site.index, e.values[0] * q[e.site.index])
    }
    fn groups(&self, _model: &NominalModel, _options: &LibraryOptions, _m: usize, j: usize) -> Vec<LibraryGroup> {
        vec![LibraryGroup {
            name: format!("encoder scale q{}", j + 1),
            type_name: self.name(),
            harmonic: None,
            joint: j,
            params: vec![(Site::at(j), 0)],
        }]
    }
    fn param_name(&self, site: Site, _component: usize) -> String {
        format!("scale q{}", site.index + 1)
    }
    fn unit(&self, _model: &NominalModel, _site: Site, _component: usize, _length: &str, _angle: &str) -> (String, bool) {
        ("(ratio)".into(), false)
    }
    fn periodic(&self) -> bool {
        false
    }
}

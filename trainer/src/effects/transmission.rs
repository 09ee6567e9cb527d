//! Transmission error, harmonic h ≥ 1 of a revolute joint: δ_j = cos · cos(h q_j) + sin · sin(h q_j).

use super::{EffectKind, EffectSpecError, FieldError, FieldType, Fields, FileUnits, Injected, Instance};
use super::{LibraryGroup, LibraryOptions, SimulatedArm, Site, Spec};
use cbd_protocol::{Effect, NominalModel};

pub struct Transmission;

/// The descriptor, as `effects::KINDS` lists it.
pub const KIND: super::Kind = super::Kind(&Transmission);

impl EffectKind for Transmission {
    fn name(&self) -> &'static str {
        "transmission"
    }
    fn components(&self) -> &'static [&'static str] {
        &["cos", "sin"]
    }
    fn from_blob(&self, effect: &Effect) -> Option<Instance> {
        let Effect::Transmission { joint, harmonic, cos, sin } = *effect else { return None };
        Some(Instance { kind: KIND, site: Site { index: joint as usize, sub: harmonic as usize }, values: vec![cos, sin] })
    }
    fn to_blob(&self, e: &Instance) -> Option<Effect> {
        Some(Effect::Transmission { joint: e.site.index as u8, harmonic: e.site.sub as u8, cos: e.values[0], sin: e.values[1] })
    }
    fn file_fields(&self) -> &'static [(&'static str, FieldType)] {
        &[("joint", FieldType::Index), ("harmonic", FieldType::Small), ("cos", FieldType::Number), ("sin", FieldType::Number)]
    }
    fn read(&self, f: &Fields, units: &FileUnits) -> Result<Instance, FieldError> {
        let (harmonic, cos, sin) = (f.small("harmonic"), f.number("cos"), f.number("sin"));
        f.check(&[("cos", cos), ("sin", sin)])?;
        if !(1..=16).contains(&harmonic) {
            return Err(f.error(format!("harmonic = {harmonic}, needs 1 to 16")));
        }
        let joint = f.index("joint")?;
        if !units.revolute[joint] {
            return Err(f.error(format!("joint {} is prismatic; a transmission harmonic needs a revolute joint", joint + 1)));
        }
        let site = Site { index: joint, sub: harmonic as usize };
        Ok(Instance { kind: KIND, site, values: vec![cos * units.rad_per_unit, sin * units.rad_per_unit] })
    }
    fn write(&self, e: &Instance, units: &FileUnits) -> String {
        format!(
            "joint = {}\nharmonic = {}\ncos = {:?}\nsin = {:?}\n",
            e.site.index + 1,
            e.site.sub,
            e.values[0] / units.rad_per_unit,
            e.values[1] / units.rad_per_unit
        )
    }
    fn parse_spec(&self, s: &Spec) -> Option<Result<Instance, EffectSpecError>> {
        Some((|| {
            let h = s.number("harmonic", None)?;
            if h.fract() != 0.0 || !(1.0..=16.0).contains(&h) {
                return Err(s.bad("harmonic must be an integer from 1 to 16".to_string()));
            }
            let joint = s.index("joint")?;
            let values = vec![s.number("cos", Some(0.0))?, s.number("sin", Some(0.0))?];
            Ok(Instance { kind: KIND, site: Site { index: joint, sub: h as usize }, values })
        })())
    }
    fn inject(&self, e: &Instance, _arm: &dyn SimulatedArm, q: &[f64]) -> Injected {
        let hq = e.site.sub as f64 * q[e.site.index];
        Injected::Joint(e.site.index, e.values[0] * hq.cos() + e.values[1] * hq.sin())
    }
    fn groups(&self, model: &NominalModel, options: &LibraryOptions, _m: usize, j: usize) -> Vec<LibraryGroup> {
        if !model.is_revolute(j) {
            return Vec::new();
        }
        (1..=options.harmonics)
            .map(|h| {
                let site = Site { index: j, sub: h as usize };
                LibraryGroup {
                    name: format!("transmission q{} harmonic {h}", j + 1),
                    type_name: self.name(),
                    harmonic: Some(h),
                    joint: j,
                    params: vec![(site, 0), (site, 1)],
                }
            })
            .collect()
    }
    fn param_name(&self, site: Site, component: usize) -> String {
        format!("q{} h{} {}", site.index + 1, site.sub, self.components()[component])
    }
    fn unit(&self, _model: &NominalModel, _site: Site, _component: usize, _length: &str, angle: &str) -> (String, bool) {
        (angle.into(), true)
    }
    fn shift_joints(&self, e: &mut Instance, offsets: &[f64]) {
        // c cos(h(q' − o)) + s sin(h(q' − o)) in terms of q'.
        let (sh, ch) = (e.site.sub as f64 * offsets[e.site.index]).sin_cos();
        let (cos, sin) = (e.values[0], e.values[1]);
        (e.values[0], e.values[1]) = (cos * ch - sin * sh, cos * sh + sin * ch);
    }
}

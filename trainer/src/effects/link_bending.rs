//! Link bending under gravity: the tool moves by compliance · (g − (g·u) u), u the unit direction
//! of link `link` (task space).

use super::{EffectKind, EffectSpecError, FieldError, FieldType, Fields, FileUnits, Injected, Instance};
use super::{LibraryGroup, LibraryOptions, SimulatedArm, Site, Spec};
use cbd_protocol::{Effect, NominalModel};
use cbd_runtime::internals::kinematics::spatial::{dot, norm, scale, sub};

pub struct LinkBending;

/// The descriptor, as `effects::KINDS` lists it.
pub const KIND: super::Kind = super::Kind(&LinkBending);

impl EffectKind for LinkBending {
    fn name(&self) -> &'static str {
        "link_bending"
    }
    fn components(&self) -> &'static [&'static str] {
        &["compliance"]
    }
    fn from_blob(&self, effect: &Effect) -> Option<Instance> {
        let Effect::LinkBending { link, compliance } = *effect else { return None };
        Some(Instance { kind: KIND, site: Site::at(link as usize), values: vec![compliance] })
    }
    fn to_blob(&self, e: &Instance) -> Option<Effect> {
        Some(Effect::LinkBending { link: e.site.index as u8, compliance: e.values[0] })
    }
    fn file_fields(&self) -> &'static [(&'static str, FieldType)] {
        &[("link", FieldType::Index), ("compliance", FieldType::Number)]
    }
    fn read(&self, f: &Fields, _units: &FileUnits) -> Result<Instance, FieldError> {
        let compliance = f.number("compliance");
        f.check(&[("compliance", compliance)])?;
        Ok(Instance { kind: KIND, site: Site::at(f.index("link")?), values: vec![compliance] })
    }
    fn write(&self, e: &Instance, _units: &FileUnits) -> String {
        format!("link = {}\ncompliance = {:?}\n", e.site.index + 1, e.values[0])
    }
    fn parse_spec(&self, s: &Spec) -> Option<Result<Instance, EffectSpecError>> {
        Some((|| {
            let link = s.index("link")?;
            Ok(Instance { kind: KIND, site: Site::at(link), values: vec![s.number("compliance", None)?] })
        })())
    }
    fn inject(&self, e: &Instance, arm: &dyn SimulatedArm, q: &[f64]) -> Injected {
        let (link, compliance) = (e.site.index, e.values[0]);
        let g = arm.gravity();
        let pts = arm.link_points(q);
        let along = sub(pts[link + 1], pts[link]);
        let len = norm(along);
        let mut b = [0.0; 3];
        if len > 0.0 {
            let u = scale(along, 1.0 / len);
            let gu = dot(g, u);
            for c in 0..3 {
                b[c] = compliance * (g[c] - gu * u[c]);
            }
        }
        Injected::Task(b)
    }
    fn groups(&self, _model: &NominalModel, _options: &LibraryOptions, _m: usize, j: usize) -> Vec<LibraryGroup> {
        vec![LibraryGroup {
            name: format!("link bending {}", j + 1),
            type_name: self.name(),
            harmonic: None,
            joint: j,
            params: vec![(Site::at(j), 0)],
        }]
    }
    fn param_name(&self, site: Site, _component: usize) -> String {
        format!("bending link {}", site.index + 1)
    }
    fn unit(&self, _model: &NominalModel, _site: Site, _component: usize, length: &str, _angle: &str) -> (String, bool) {
        (length.into(), false)
    }
    fn task_space(&self) -> bool {
        true
    }
}

//! A new effect by its descriptor alone (docs/DESIGN.md §4, "Worked changes (issue 41)"): a test
//! kind, `index_step` (δ_j = step · sign(q_j): joint j reads `step` off on one side of its zero and
//! −step on the other, an encoder index misplaced), written only here, is injected by the
//! simulator, parsed from `--effect`, read from and written to a model file's `[[effects]]`, and
//! offered and found by `cbd diagnose`'s library. What it cannot do without a blob variant
//! (`cbd_protocol::Effect`, `protocol/src/validate.rs`) and the runtime's evaluation
//! (`runtime/src/kinematics/augmented.rs`): live in a `NominalModel` — so not be applied by
//! refinement, written by `--write-model` or evaluated by a blob.

use crate::data::effects_section::write_entry;
use crate::data::Measurements;
use crate::effects::{EffectKind, EffectSpecError, FieldError, FieldType, Fields, FileUnits, Injected, Instance, Kind};
use crate::effects::{LibraryGroup, LibraryOptions, RawEffect, Response, SimulatedArm, Site, Spec};
use crate::simulate::effects::{parse_effect_of, EffectArm};
use cbd_protocol::{Effect, NominalModel};

struct IndexStep;

const STEP: Kind = Kind(&IndexStep);

impl EffectKind for IndexStep {
    fn name(&self) -> &'static str {
        "index_step"
    }
    fn components(&self) -> &'static [&'static str] {
        &["step"]
    }
    fn from_blob(&self, _effect: &Effect) -> Option<Instance> {
        None
    }
    fn to_blob(&self, _e: &Instance) -> Option<Effect> {
        None
    }
    fn file_fields(&self) -> &'static [(&'static str, FieldType)] {
        &[("joint", FieldType::Index), ("step", FieldType::Number)]
    }
    fn read(&self, f: &Fields, units: &FileUnits) -> Result<Instance, FieldError> {
        let step = f.number("step");
        f.check(&[("step", step)])?;
        Ok(Instance { kind: STEP, site: Site::at(f.index("joint")?), values: vec![step * units.rad_per_unit] })
    }
    fn write(&self, e: &Instance, units: &FileUnits) -> String {
        format!("joint = {}\nstep = {:?}\n", e.site.index + 1, e.values[0] / units.rad_per_unit)
    }
    fn parse_spec(&self, s: &Spec) -> Option<Result<Instance, EffectSpecError>> {
        Some((|| Ok(Instance { kind: STEP, site: Site::at(s.index("joint")?), values: vec![s.number("step", None)?] }))())
    }
    fn inject(&self, e: &Instance, _arm: &dyn SimulatedArm, q: &[f64]) -> Injected {
        Injected::Joint(e.site.index, e.values[0] * q[e.site.index].signum())
    }
    fn groups(&self, _model: &NominalModel, _options: &LibraryOptions, _m: usize, j: usize) -> Vec<LibraryGroup> {
        let params = vec![(Site::at(j), 0)];
        vec![LibraryGroup { name: format!("index step q{}", j + 1), type_name: self.name(), harmonic: None, joint: j, params }]
    }
    fn param_name(&self, site: Site, _component: usize) -> String {
        format!("step q{}", site.index + 1)
    }
    fn unit(&self, _model: &NominalModel, _site: Site, _component: usize, _length: &str, angle: &str) -> (String, bool) {
        (angle.into(), true)
    }
    /// No blob form: the response is the deflection itself.
    fn response(&self, _model: &NominalModel, e: &Instance, q: &[f64]) -> Response {
        let mut delta = vec![0.0; q.len()];
        delta[e.site.index] = e.values[0] * q[e.site.index].signum();
        Response::Joint(delta)
    }
}

fn step(joint: usize, value: f64) -> Instance {
    Instance { kind: STEP, site: Site::at(joint), values: vec![value] }
}

#[test]
fn the_simulator_injects_it_and_the_effect_spec_names_it() {
    let rigid = crate::simulate::rr::nominal();
    let arm = EffectArm::new(rigid.clone()).with(step(1, 0.01));
    for q in [[0.3f64, 1.1], [-0.4, -2.0]] {
        let deflected = [q[0], q[1] + 0.01 * q[1].signum()];
        assert_eq!(arm.deflection(&q), [0.0, 0.01 * q[1].signum()]);
        assert_eq!(arm.position(&q, 0), cbd_runtime::internals::kinematics::forward_kinematics(&rigid, &deflected).position[..2].to_vec());
    }
    let parsed = parse_effect_of(&[STEP], "index_step:joint=2,step=0.01", 2).unwrap();
    assert_eq!(parsed, step(1, 0.01).into());
    let e = parse_effect_of(&[STEP], "index_step:joint=3,step=0.01", 2).unwrap_err().to_string();
    assert!(e.contains("joint must be between 1 and 2"), "{e}");
    let e = parse_effect_of(&[STEP], "wobble:joint=1", 2).unwrap_err().to_string();
    assert!(e.contains("unknown type `wobble` (index_step, bump, dead_zone, thermal, drift)"), "{e}");
}

#[test]
fn the_model_file_reads_and_writes_it() {
    let entry = |text: &str| -> Result<RawEffect, toml::de::Error> {
        let mut doc: toml::Table = toml::from_str(text).unwrap();
        let toml::Value::Array(mut entries) = doc.remove("effects").unwrap() else { panic!("{text}") };
        let toml::Value::Table(table) = entries.remove(0) else { panic!("{text}") };
        RawEffect::from_table(table, &[STEP])
    };
    let revolute = [true, true];
    for rad_per_unit in [1.0, std::f64::consts::PI / 180.0] {
        let units = FileUnits { rad_per_unit, revolute: &revolute };
        let written = write_entry(&step(1, 0.01), &units);
        assert!(written.starts_with("\n[[effects]]\ntype = \"index_step\"\njoint = 2\nstep = "), "{written}");
        let back = entry(&written).unwrap().read(1, &units).unwrap();
        assert_eq!(back.site, Site::at(1));
        assert!((back.values[0] - 0.01).abs() <= 1e-17, "{written}: {back:?}");
        assert_eq!(write_entry(&back, &units), written);
    }
    let units = FileUnits { rad_per_unit: 1.0, revolute: &revolute };
    let e = entry("[[effects]]\ntype = \"index_step\"\njoint = 3\nstep = 0.01\n").unwrap().read(2, &units).unwrap_err();
    assert_eq!(e.to_string(), "[[effects]] entry 2: joint = 3, the model has 2 (1 to 2)");
    let e = entry("[[effects]]\ntype = \"index_step\"\njoint = 1\nstep = 1e300\n").unwrap().read(1, &units).unwrap_err();
    assert!(e.to_string().contains("step = 1e300 is beyond"), "{e}");
    let e = entry("[[effects]]\ntype = \"index_step\"\njoint = 1\nsteps = 0.01\n").unwrap_err().to_string();
    assert!(e.contains("unknown field `steps`, expected `joint` or `step`"), "{e}");
    let e = entry("[[effects]]\ntype = \"index_stop\"\njoint = 1\n").unwrap_err().to_string();
    assert!(e.contains("unknown variant `index_stop`, expected one of `index_step`"), "{e}");
    // Without a blob variant it cannot enter a model.
    assert_eq!(step(1, 0.01).to_blob(), None);
}

#[test]
fn the_library_offers_and_finds_it() {
    use super::library::{candidate_groups_of, jacobian, GroupKind, Param};
    use super::selection::{forward_select, LinearProblem, SelectionOptions};
    let planar = crate::simulate::rr::nominal();
    let model = crate::nominal::planar::as_dh(&planar);
    let groups = candidate_groups_of(&[STEP], &model, &LibraryOptions::default(), 2);
    let names: Vec<&str> = groups.iter().map(|g| g.name.as_str()).collect();
    assert_eq!(names, ["geometric", "index step q1", "index step q2"]);
    assert_eq!(groups[2].kind, GroupKind::effect("index_step", None));
    // Data of the arm with a step of 5 mrad on joint 2.
    let truth = 5e-3;
    let arm = EffectArm::new(planar).with(step(1, truth));
    // Both sides of every joint's zero: uniform in [−π, π).
    let sampling = crate::simulate::Sampling::Uniform { count: 120, seed: 7 };
    let joints: Vec<f64> = crate::simulate::configurations(sampling, 2).iter().map(|q| q - std::f64::consts::PI).collect();
    let data: Measurements = arm.measure(&joints, 1e-5, 3);
    let params: Vec<Param> = groups.iter().flat_map(|g| g.params.clone()).collect();
    let offsets: Vec<usize> = groups.iter().scan(0, |at, g| Some(std::mem::replace(at, *at + g.params.len()))).collect();
    let jac = jacobian(&model, &data, &params);
    let group_cols = super::usable_columns(&groups, &offsets, &jac, 1e-5);
    assert!(!group_cols[2].is_empty(), "the step's column is independent of the geometric ones");
    let residual = data.residual_of(&model);
    let options = SelectionOptions::default();
    let problem = LinearProblem::new(&jac, &residual, 2, 1, data.order, options.folds, options.seed);
    let selection = forward_select(&problem, &group_cols, &options);
    assert!(selection.selected.contains(&2) && !selection.selected.contains(&1), "{selection:?}");
    let (values, _) = problem.fit(&group_cols[2]);
    assert!((values[0] - truth).abs() < 0.02 * truth, "{values:?} vs {truth}");
    assert_eq!(super::library::param_name(&model, &params[group_cols[2][0]]), "step q2");
}

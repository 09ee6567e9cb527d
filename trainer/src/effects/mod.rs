//! One descriptor per physical effect kind (docs/DESIGN.md §7): its name, parameters and units,
//! its model-file entry (read and written), what the simulator injects, its candidate groups and
//! Jacobian columns in `cbd diagnose`'s library and its report labels. The model file's
//! `[[effects]]` (`data::effects_section`), the simulator (`simulate::effects`), the library
//! (`diagnose::library`, `diagnose::report`), the planar frame (`nominal::planar`) and the
//! command check (`evaluation::command_check`) iterate over [`KINDS`] instead of matching on the
//! effect types. A new effect is a file here and its entry in [`KINDS`], plus its blob variant
//! (`cbd_protocol::Effect`, validated in `protocol/src/validate.rs`) and the runtime's evaluation
//! of it (`runtime/src/kinematics/augmented.rs`).

pub mod encoder_scale;
pub mod gravity_compliance;
pub mod gravity_moment;
pub mod link_bending;
pub mod transmission;

use cbd_protocol::{Effect, NominalModel};
use cbd_runtime::internals::kinematics::augmented::{effect_terms, Order};
use std::collections::BTreeMap;

/// Every effect kind, in the order the library offers them at a joint and `--effect` lists them.
pub static KINDS: &[Kind] = &[encoder_scale::KIND, transmission::KIND, gravity_compliance::KIND, gravity_moment::KIND, link_bending::KIND];

/// Where an effect acts: `index` its 0-based joint (or link), `sub` what else names it (a
/// transmission's harmonic, a gravity moment's link; 0 otherwise).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Default)]
pub struct Site {
    pub index: usize,
    pub sub: usize,
}

impl Site {
    pub fn at(index: usize) -> Site {
        Site { index, sub: 0 }
    }
}

/// One effect: its kind, where it acts and its parameter values (in [`EffectKind::components`]'s
/// order; angles in radians, lengths in the model's unit).
#[derive(Debug, Clone, PartialEq)]
pub struct Instance {
    pub kind: Kind,
    pub site: Site,
    pub values: Vec<f64>,
}

impl Instance {
    /// The descriptor's form of a blob effect (every blob effect has a kind in [`KINDS`]).
    pub fn of(effect: &Effect) -> Instance {
        KINDS.iter().find_map(|k| k.from_blob(effect)).expect("every blob effect has a descriptor in effects::KINDS")
    }

    /// Parameter `component` of `kind` at `site` with value `v`, every other parameter zero.
    pub fn single(kind: Kind, site: Site, component: usize, v: f64) -> Instance {
        let mut values = vec![0.0; kind.components().len()];
        values[component] = v;
        Instance { kind, site, values }
    }

    /// The blob's form; `None` for a kind the blob cannot hold.
    pub fn to_blob(&self) -> Option<Effect> {
        self.kind.to_blob(self)
    }
}

/// A descriptor, compared and ordered by name.
#[derive(Clone, Copy)]
pub struct Kind(pub &'static dyn EffectKind);

impl std::ops::Deref for Kind {
    type Target = dyn EffectKind;
    fn deref(&self) -> &(dyn EffectKind + 'static) {
        self.0
    }
}

impl std::fmt::Debug for Kind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.0.name())
    }
}

impl PartialEq for Kind {
    fn eq(&self, other: &Kind) -> bool {
        self.0.name() == other.0.name()
    }
}

impl Eq for Kind {}

impl PartialOrd for Kind {
    fn partial_cmp(&self, other: &Kind) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}

impl Ord for Kind {
    fn cmp(&self, other: &Kind) -> std::cmp::Ordering {
        self.0.name().cmp(other.0.name())
    }
}

/// The kind named `name` among `kinds`.
pub fn named(kinds: &[Kind], name: &str) -> Option<Kind> {
    kinds.iter().copied().find(|k| k.name() == name)
}

/// One physical effect kind. Defaults: not in the model file's `[[effects]]` (no
/// [`file_fields`](EffectKind::file_fields)), not a `--effect` type, no library group, a joint
/// deflection whose response the runtime evaluates from the blob form, periodic in its joint.
pub trait EffectKind: Sync {
    /// The `type` in model files, `--effect` specs and `cbd diagnose --json`.
    fn name(&self) -> &'static str;
    /// Its parameters' names, in [`Instance::values`]'s order.
    fn components(&self) -> &'static [&'static str];
    /// This kind's form of a blob effect (`None`: another kind's).
    fn from_blob(&self, effect: &Effect) -> Option<Instance>;
    /// The blob's form (`None`: the blob has no variant for it).
    fn to_blob(&self, e: &Instance) -> Option<Effect>;

    /// The keys of its `[[effects]]` entry besides `type`, with their types (empty: no entry).
    fn file_fields(&self) -> &'static [(&'static str, FieldType)] {
        &[]
    }
    /// Its `[[effects]]` entry read (1-based indices and angles in the file's units).
    fn read(&self, _fields: &Fields, _units: &FileUnits) -> Result<Instance, FieldError> {
        unreachable!("{} has no [[effects]] entry", self.name())
    }
    /// Its `[[effects]]` entry's lines after `type = "…"` (what [`read`](EffectKind::read) reads back).
    fn write(&self, _e: &Instance, _units: &FileUnits) -> String {
        String::new()
    }

    /// A `--effect name:key=value,...` of this kind (`None`: not an `--effect` type).
    fn parse_spec(&self, _spec: &Spec) -> Option<Result<Instance, EffectSpecError>> {
        None
    }
    /// What the simulator's independent implementation adds at commanded joints `q`.
    fn inject(&self, e: &Instance, arm: &dyn SimulatedArm, q: &[f64]) -> Injected;

    /// The library's candidate groups of this kind at joint (or link) `joint` for data of `m`
    /// task coordinates.
    fn groups(&self, _model: &NominalModel, _options: &LibraryOptions, _m: usize, _joint: usize) -> Vec<LibraryGroup> {
        Vec::new()
    }
    /// A parameter's name in the report (1-based joints), e.g. `q3 h2 cos`.
    fn param_name(&self, site: Site, component: usize) -> String;
    /// A parameter's unit as printed, and whether its value is per radian (shown ÷ the angle unit).
    fn unit(&self, model: &NominalModel, site: Site, component: usize, length: &str, angle: &str) -> (String, bool);
    /// Whether it acts in task space (b) rather than on a joint (δ).
    fn task_space(&self) -> bool {
        false
    }
    /// What the effect adds at q with its own values, as the diagnosis needs it: by default the
    /// runtime's evaluation of its blob form.
    fn response(&self, model: &NominalModel, e: &Instance, q: &[f64]) -> Response {
        let effect = self.to_blob(e).expect("an effect without a blob form gives its own response");
        let t = effect_terms(model, std::slice::from_ref(&effect), q, Order::Value);
        if self.task_space() {
            Response::Task(t.b)
        } else {
            Response::Joint(t.delta.iter().copied().take(q.len()).collect())
        }
    }
    /// Whether the library keeps only the identifiable combinations of a group's columns (a
    /// regressor) rather than the whole group or none of it.
    fn regressor(&self) -> bool {
        false
    }
    /// Whether the model repeats after a whole turn of the effect's joint.
    fn periodic(&self) -> bool {
        true
    }
    /// The effect in a chain whose joint k reads q_k − `offsets[k]` (`nominal::planar::as_planar_in_frame`).
    fn shift_joints(&self, _e: &mut Instance, _offsets: &[f64]) {}
}

/// The contribution of one effect at q: to δ (joint) or to b (task).
#[derive(Debug, Clone, PartialEq)]
pub enum Response {
    Joint(Vec<f64>),
    Task([f64; 3]),
}

/// What the simulator adds for one effect: `Joint(j, v)` to δ_j, `Task(v)` to b.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Injected {
    Joint(usize, f64),
    Task([f64; 3]),
}

/// The simulated arm an effect is injected into (`simulate::effects::EffectArm`, its own frame
/// walk and numerical gravity torques: an independent check of the runtime).
pub trait SimulatedArm {
    /// τ(q) of the arm's mass model.
    fn gravity_torques(&self, q: &[f64]) -> Vec<f64>;
    /// ∂/∂q_joint g·(mass·o_link(q) + R_link(q)·first_moment).
    fn moment_torque(&self, q: &[f64], joint: usize, link: usize, mass: f64, first_moment: [f64; 3]) -> f64;
    /// The start of link 0 and the distal end of every link.
    fn link_points(&self, q: &[f64]) -> Vec<[f64; 3]>;
    /// The gravity direction (task space).
    fn gravity(&self) -> [f64; 3];
}

/// Settings of `cbd diagnose`'s library.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LibraryOptions {
    /// Transmission harmonics 1..=H per revolute joint.
    pub harmonics: u8,
}

impl Default for LibraryOptions {
    fn default() -> Self {
        LibraryOptions { harmonics: 3 }
    }
}

/// One candidate group a kind offers: its name, the `type` it reports, a harmonic for the JSON,
/// its joint (or link) and its parameters as (site, component).
#[derive(Debug, Clone, PartialEq)]
pub struct LibraryGroup {
    pub name: String,
    pub type_name: &'static str,
    pub harmonic: Option<u8>,
    pub joint: usize,
    pub params: Vec<(Site, usize)>,
}

/// The type of an `[[effects]]` key.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum FieldType {
    /// A 1-based joint or link (`usize`).
    Index,
    /// A small count (`u8`: a harmonic).
    Small,
    /// A number (`f64`).
    Number,
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum FieldValue {
    Index(usize),
    Small(u8),
    Number(f64),
}

/// The units and joints of the model a file's effects belong to.
#[derive(Debug, Clone, Copy)]
pub struct FileUnits<'a> {
    /// Radians per angle unit of the file.
    pub rad_per_unit: f64,
    /// Per joint: revolute (angles) or prismatic (lengths).
    pub revolute: &'a [bool],
}

impl FileUnits<'_> {
    /// The unit a revolute joint's deflection is in, 1 for a prismatic one's.
    pub fn joint_unit(&self, joint: usize) -> f64 {
        if self.revolute[joint] {
            self.rad_per_unit
        } else {
            1.0
        }
    }
}

/// A `[gravity]` or `[[effects]]` value that is not valid: `field` names it (`[[effects]] entry 2`,
/// `[gravity] link_masses`), `message` says what is wrong. The model file reader adds the file.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{field}: {message}")]
pub struct FieldError {
    pub field: String,
    pub message: String,
}

impl FieldError {
    pub fn new(field: impl Into<String>, message: impl Into<String>) -> FieldError {
        FieldError { field: field.into(), message: message.into() }
    }
}

/// One `[[effects]]` entry as written in the file: its kind and typed values (checked against
/// the kind's keys when the TOML is read).
#[derive(Debug, Clone)]
pub struct RawEffect {
    pub kind: Kind,
    values: Vec<(&'static str, FieldValue)>,
}

impl RawEffect {
    /// A TOML table as an entry of one of `kinds`: serde's messages for an unknown `type`, an
    /// unknown or missing key and a value of the wrong type.
    pub fn from_table<E: serde::de::Error>(mut table: toml::Table, kinds: &[Kind]) -> Result<RawEffect, E> {
        let in_file: Vec<Kind> = kinds.iter().copied().filter(|k| !k.file_fields().is_empty()).collect();
        let name = match table.remove("type") {
            Some(toml::Value::String(s)) => s,
            Some(other) => return Err(E::custom(format!("invalid type: {}, expected a string", other.type_str()))),
            None => return Err(E::missing_field("type")),
        };
        let Some(kind) = named(&in_file, &name) else {
            let names: Vec<String> = in_file.iter().map(|k| format!("`{}`", k.name())).collect();
            return Err(E::custom(format!("unknown variant `{name}`, expected one of {}", names.join(", "))));
        };
        let fields = kind.file_fields();
        if let Some(key) = table.keys().find(|k| !fields.iter().any(|(f, _)| f == k)) {
            let keys: Vec<&str> = fields.iter().map(|(f, _)| *f).collect();
            return Err(E::custom(format!("unknown field `{key}`, {}", expected(&keys))));
        }
        let mut values = Vec::new();
        for &(key, ty) in fields {
            let Some(v) = table.remove(key) else { return Err(E::missing_field(key)) };
            let v = match ty {
                FieldType::Index => FieldValue::Index(serde::Deserialize::deserialize(v).map_err(E::custom)?),
                FieldType::Small => FieldValue::Small(serde::Deserialize::deserialize(v).map_err(E::custom)?),
                FieldType::Number => FieldValue::Number(serde::Deserialize::deserialize(v).map_err(E::custom)?),
            };
            values.push((key, v));
        }
        Ok(RawEffect { kind, values })
    }

    /// The entry read by its kind; `entry` is its 1-based place in the file.
    pub fn read(&self, entry: usize, units: &FileUnits) -> Result<Instance, FieldError> {
        self.kind.read(&Fields { entry, raw: self, n: units.revolute.len() }, units)
    }
}

/// serde's wording of the keys it expected.
fn expected(keys: &[&str]) -> String {
    match keys {
        [] => "there are no fields".into(),
        [a] => format!("expected `{a}`"),
        [a, b] => format!("expected `{a}` or `{b}`"),
        _ => format!("expected one of {}", keys.iter().map(|k| format!("`{k}`")).collect::<Vec<_>>().join(", ")),
    }
}

impl<'de> serde::Deserialize<'de> for RawEffect {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<RawEffect, D::Error> {
        RawEffect::from_table(toml::Table::deserialize(deserializer)?, KINDS)
    }
}

/// The values of one `[[effects]]` entry, as a kind's [`read`](EffectKind::read) sees them.
pub struct Fields<'a> {
    entry: usize,
    raw: &'a RawEffect,
    n: usize,
}

impl Fields<'_> {
    fn value(&self, key: &str) -> FieldValue {
        self.raw.values.iter().find(|(k, _)| *k == key).map(|(_, v)| *v).unwrap_or_else(|| panic!("{key} is not a file field"))
    }

    /// How an error names this entry: `[[effects]] entry 2`.
    pub fn at(&self) -> String {
        format!("[[effects]] entry {}", self.entry)
    }

    /// An error naming this entry.
    pub fn error(&self, message: impl Into<String>) -> FieldError {
        FieldError::new(self.at(), message)
    }

    /// A number.
    pub fn number(&self, key: &str) -> f64 {
        match self.value(key) {
            FieldValue::Number(v) => v,
            _ => panic!("{key} is not a number"),
        }
    }

    /// A small count.
    pub fn small(&self, key: &str) -> u8 {
        match self.value(key) {
            FieldValue::Small(v) => v,
            _ => panic!("{key} is not a small count"),
        }
    }

    /// A 1-based joint or link of the model, 0-based.
    pub fn index(&self, key: &str) -> Result<usize, FieldError> {
        let FieldValue::Index(value) = self.value(key) else { panic!("{key} is not an index") };
        let n = self.n;
        if value == 0 || value > n {
            return Err(self.error(format!("{key} = {value}, the model has {n} (1 to {n})")));
        }
        Ok(value - 1)
    }

    /// Every named value finite and within the importer's bound.
    pub fn check(&self, values: &[(&str, f64)]) -> Result<(), FieldError> {
        check_values(&self.at(), values)
    }
}

/// Finite and within the importer's magnitude bound (squares must stay finite downstream).
pub fn check_values(at: &str, values: &[(&str, f64)]) -> Result<(), FieldError> {
    values.iter().try_for_each(|(name, v)| check_effect_value(name, *v)).map_err(|e| FieldError::new(at, e.to_string()))
}

/// One value of an effect, in a model file or a simulation's `--effect`: finite and within the
/// importer's bound ±1e100, so that what `cbd simulate` injects a model file could declare.
pub fn check_effect_value(name: &str, v: f64) -> Result<(), EffectValueError> {
    use crate::limits::MAX_MAGNITUDE;
    if !v.is_finite() {
        Err(EffectValueError::NotFinite { name: name.into(), value: v })
    } else if v.abs() > MAX_MAGNITUDE {
        Err(EffectValueError::TooLarge { name: name.into(), value: v })
    } else {
        Ok(())
    }
}

/// An effect's value out of range ([`check_effect_value`], [`encoder_scale::check_encoder_scale`]):
/// `name` is the value's key (`compliance`, `scale`).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum EffectValueError {
    #[error("{name} = {} is not finite", crate::error::as_written(*value))]
    NotFinite { name: String, value: f64 },
    #[error("{name} = {} is beyond ±{:e}", crate::error::as_written(*value), crate::limits::MAX_MAGNITUDE)]
    TooLarge { name: String, value: f64 },
    #[error("scale = {}: an encoder scale error must lie within (-1, 1)", crate::error::as_written(*scale))]
    EncoderScale { scale: f64 },
}

/// A `--effect` specification that does not parse: the spec and what is wrong with it.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("--effect {spec}: {reason}")]
pub struct EffectSpecError {
    pub spec: String,
    pub reason: String,
}

impl From<EffectSpecError> for crate::Error {
    fn from(e: EffectSpecError) -> crate::Error {
        crate::Error::stage("effects", e)
    }
}

/// A `--effect type:key=value,...` split into its type and keys (joints and links 1-based).
pub struct Spec {
    text: String,
    kv: BTreeMap<String, String>,
    n_joints: usize,
    /// The keys a parser asked for ([`check_all_read`](Spec::check_all_read): any other is unknown).
    read: std::cell::RefCell<std::collections::BTreeSet<String>>,
}

impl Spec {
    /// The spec's type and keys, for a chain of `n_joints` joints.
    pub fn parse(spec: &str, n_joints: usize) -> Result<(String, Spec), EffectSpecError> {
        let (kind, rest) = spec.split_once(':').unwrap_or((spec, ""));
        let mut out = Spec { text: spec.to_string(), kv: BTreeMap::new(), n_joints, read: Default::default() };
        for part in rest.split(',').filter(|p| !p.trim().is_empty()) {
            let (k, v) = part.split_once('=').ok_or_else(|| out.bad(format!("`{}` is not key=value", crate::error::excerpt(part))))?;
            if out.kv.insert(k.trim().to_string(), v.trim().to_string()).is_some() {
                return Err(out.bad(format!("{}= is given twice", crate::error::excerpt(k.trim()))));
            }
        }
        Ok((kind.to_string(), out))
    }

    /// An error naming the spec.
    pub fn bad(&self, reason: String) -> EffectSpecError {
        EffectSpecError { spec: crate::error::excerpt_of(&self.text, 120), reason }
    }

    /// The raw text of key `k`.
    pub fn get(&self, k: &str) -> Option<&str> {
        self.read.borrow_mut().insert(k.to_string());
        self.kv.get(k).map(String::as_str)
    }

    /// An error naming the first key no parser asked for (a misspelt or foreign key), and the
    /// keys that were asked for.
    pub fn check_all_read(&self) -> Result<(), EffectSpecError> {
        let read = self.read.borrow();
        match self.kv.keys().find(|k| !read.contains(*k)) {
            Some(k) => {
                let known: Vec<&str> = read.iter().map(String::as_str).collect();
                Err(self.bad(format!("unknown key `{}` (this type takes {})", crate::error::excerpt(k), known.join(", "))))
            }
            None => Ok(()),
        }
    }

    /// A finite number within the model file's bound, or `default` when absent.
    pub fn number(&self, k: &str, default: Option<f64>) -> Result<f64, EffectSpecError> {
        match self.get(k) {
            Some(v) => {
                let x = v.parse::<f64>().ok().filter(|x| x.is_finite());
                let x = x.ok_or_else(|| self.bad(format!("{k}={} is not a finite number", crate::error::excerpt(v))))?;
                // The model file's bound on effect values: what is injected could be declared.
                check_effect_value(k, x).map_err(|e| self.bad(e.to_string()))?;
                Ok(x)
            }
            None => default.ok_or_else(|| self.bad(format!("missing {k}="))),
        }
    }

    /// A 1-based joint (or link), 0-based.
    pub fn index(&self, k: &str) -> Result<usize, EffectSpecError> {
        let v = self.number(k, None)?;
        if v.fract() != 0.0 || v < 1.0 || v > self.n_joints as f64 {
            return Err(self.bad(format!("{k} must be between 1 and {}", self.n_joints)));
        }
        Ok(v as usize - 1)
    }
}

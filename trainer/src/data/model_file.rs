//! The model file (TOML): a nominal serial chain and how its measurements are stored.
//!
//! ```toml
//! name = "UR5"
//! length_unit = "mm"          # "um" | "mm" | "cm" | "m" | "in": unit of every length in this file and of the model
//! angle_unit = "deg"          # "deg" | "rad": unit of every angle in this file
//!
//! [chain]                     # a DH table …
//! convention = "standard"     # "standard": Rz(θ) Tz(d) Tx(a) Rx(α); "modified" (Craig): Rx(α) Tx(a) Rz(θ) Tz(d)
//! joints = [                  # kind = "revolute" (default) | "prismatic"; theta_offset defaults to 0
//!   { a = 0, alpha = 90, d = 89.159 },
//!   { a = -425, alpha = 0, d = 0, theta_offset = 0, kind = "revolute" },
//! ]
//! base = { translation = [0, 0, 0], rpy = [0, 0, 0] }   # optional (absent: identity); rpy = URDF's Rz(y) Ry(p) Rx(r)
//!                             # base = { register = true }: unknown (a tracker's frame), registered on the data
//! tool = { translation = [0, 0, 31] }                    # or rotation = [[..], [..], [..]] (rows)
//!                             # tool = { …, points = [[0, 0, 0], [100, 0, 0], [50, 86.6, 0]] }: several
//!                             # measured points (offsets in the tool frame, length_unit; at most 4)
//!
//! # [urdf]                    # … or a URDF chain (exactly one of [chain], [urdf], [planar])
//! # path = "robot.urdf"       # relative to this file; URDF lengths are metres, converted to length_unit
//! # base_link = "base_link"
//! # tip_link = "tool0"
//!
//! # [planar]                  # … or a planar arm of revolute joints (2-D task space)
//! # lengths = [1.0, 0.5]
//! # base = [0.03, -0.02]      # optional: y = R(yaw) k0(q + offsets) + base (length_unit,
//! # yaw = 0.5                 #   angle_unit); the measurements are read into the chain's frame
//! # offsets = [0.4, -0.7]     #   (joints + offsets, R(−yaw)(y − base)) at import
//!
//! [measurements]              # optional: the CSV columns
//! joints = ["q1_deg", "q2_deg"]        # one per joint, in chain order
//! positions = ["x_mm", "y_mm", "z_mm"] # one per task coordinate (per tool point, in the order of
//!                             # tool.points: x1, y1, z1, x2, …)
//! # pose = { position = ["x", "y", "z"], quaternion = ["qw", "qx", "qy", "qz"] }  # instead of
//! #                           # positions: a measured tool pose (or rotation = 9 columns, row-major),
//! #                           # read as the tool points y_j = p + R p_j
//! angle_unit = "deg"          # unit of revolute joint columns (default: angle_unit above)
//! length_unit = "mm"          # unit of position and prismatic joint columns (default: length_unit above)
//! min_rows = 10               # fewer data rows is an error (default 1)
//! joint_limits = [[-360, 360], [-360, 360]]  # [lo, hi] per joint in the column units; a value outside
//!                             # is an error (default: ±1 turn for revolute joints, none for prismatic)
//! repeat_tolerance = 0.5      # rows with equal joints whose positions differ by more are an error
//!                             # (length_unit above; default 1e-3 of the positions' bounding-box diagonal)
//! order = "measured"          # the rows are in measurement order (default): held-out rows are
//!                             # contiguous blocks; "unordered" (a grid, a shuffled file): interleaved
//!
//! [measurements.joint_map]    # optional: controller joint values (columns) → model joints,
//! sign = { q3 = -1 }          # q_i = sign_i · scale_i · Σ_j coupling_ij c_j + offset_i in the
//! coupling = [[1, 0], [1, 1]] # columns' units (see `data::joint_map`)
//!
//! # [gravity] and [[effects]]: physical effects on top of the chain (see `data::effects_section`)
//! ```
//!
//! Inside the program the model works in the file's length unit and in radians.
//! Unknown fields are errors that name the field.

use super::csv_import::{default_joint_limits, ColumnSpec, OrientationColumns};
use super::effects_section;
use super::joint_map::{JointMap, RawJointMap};
use crate::error::number;
use crate::limits::MAX_MAGNITUDE;
use crate::nominal::planar::PlanarFrame;
use cbd_protocol::{JointKind, NominalModel};
use raw::RawModelFile;
use serde::Deserialize;
use std::path::{Path, PathBuf};

mod exact;
mod numbers;
mod raw;
mod sections;
mod toml_error;
mod writer;

pub use super::import_error::ImportError;
pub use super::units::{AngleUnit, LengthUnit};
pub use writer::write_model_file;

/// A loaded model file.
#[derive(Debug, Clone, PartialEq)]
pub struct ModelFile {
    /// Where it was read from (for messages and relative paths).
    pub path: PathBuf,
    pub name: Option<String>,
    /// Lengths in `length_unit`, angles in radians.
    pub nominal: NominalModel,
    /// The model's length unit (= the file's).
    pub length_unit: LengthUnit,
    /// The unit angles were written in (the model itself uses radians).
    pub angle_unit: AngleUnit,
    /// Joint names: from the URDF, or `q1 … qn`.
    pub joint_names: Vec<String>,
    /// The `[measurements]` section, if any.
    pub measurements: Option<MeasurementSection>,
    /// Its joint mapping, checked against the model's joints.
    pub joint_map: Option<JointMap>,
    /// `[planar]`'s base, yaw and joint offsets (radians): the chain sits in this frame.
    pub planar_frame: Option<PlanarFrame>,
    /// `[chain] base = { register = true }`: the base is unknown (identity in `nominal`) and is
    /// registered on the training data (`parametric::base_registration`).
    pub register_base: bool,
    /// `[urdf]`: the URDF the chain was read from (`cbd export` rewrites its origins).
    pub urdf: Option<UrdfSource>,
}

/// Where a `[urdf]` model's chain comes from.
#[derive(Debug, Clone, PartialEq)]
pub struct UrdfSource {
    /// The URDF file (relative paths resolved against the model file's folder).
    pub path: PathBuf,
    pub base_link: String,
    pub tip_link: String,
}

/// `[measurements] pose`: a measured tool pose's columns — its position and a unit quaternion
/// (w, x, y, z) or a rotation matrix (9 columns, row-major), the tool frame in the task frame.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PoseSection {
    pub position: Vec<String>,
    pub quaternion: Option<Vec<String>>,
    pub rotation: Option<Vec<String>>,
}

/// The `[measurements]` section: CSV column names and units.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MeasurementSection {
    pub joints: Vec<String>,
    /// One per task coordinate, per tool point (x1, y1, z1, x2, …); empty when `pose` is given.
    #[serde(default)]
    pub positions: Vec<String>,
    /// A measured pose instead of `positions`, read as the tool points.
    pub pose: Option<PoseSection>,
    pub angle_unit: Option<AngleUnit>,
    pub length_unit: Option<LengthUnit>,
    pub min_rows: Option<usize>,
    /// `[lo, hi]` per joint, in the columns' units (angle_unit / length_unit of this section).
    #[serde(default, deserialize_with = "exact::optional_list")]
    pub joint_limits: Option<Vec<[f64; 2]>>,
    /// Largest distance (length_unit of this section) between positions of repeated joint configurations.
    pub repeat_tolerance: Option<f64>,
    /// `[measurements.joint_map]`: controller joint values → model joints (`data::joint_map`).
    pub joint_map: Option<RawJointMap>,
    /// "measured" (default: the rows are a time sequence) or "unordered" ([`crate::data::RowOrder`]).
    pub order: Option<crate::data::RowOrder>,
}

impl ModelFile {
    /// Column specification for [`crate::data::csv_import::read_measurements`]: from the
    /// `[measurements]` section, or an error if the file has none.
    pub fn column_spec(&self) -> Result<ColumnSpec, ImportError> {
        let section = self.measurements.as_ref().ok_or_else(|| ImportError::Model {
            file: self.path.clone(),
            message: "no [measurements] section: name the CSV columns in one, e.g. `[measurements]` `joints = [\"q1\", \"q2\"]` `positions = [\"x\", \"y\"]`".into(),
        })?;
        let (positions, orientation) = match &section.pose {
            Some(pose) => {
                let orientation = match (&pose.quaternion, &pose.rotation) {
                    (Some(q), _) => OrientationColumns::Quaternion(q.clone()),
                    (None, Some(r)) => OrientationColumns::Rotation(r.clone()),
                    (None, None) => unreachable!("checked when the file was read"),
                };
                (pose.position.clone(), Some(orientation))
            }
            None => (section.positions.clone(), None),
        };
        let spec = ColumnSpec {
            tool_points: self.nominal.tool_points().to_vec(),
            orientation_columns: orientation,
            ..self.column_spec_with(section.joints.clone(), positions)
        };
        let angle_unit = section.angle_unit.unwrap_or(self.angle_unit);
        let length_unit = section.length_unit.unwrap_or(self.length_unit);
        let model_err = |message: String| ImportError::Model { file: self.path.clone(), message };
        let length_factor = length_unit.factor_to(self.length_unit);
        let joint_limits = match &section.joint_limits {
            None => spec.joint_limits.clone(),
            Some(limits) => {
                if limits.len() != spec.joint_kinds.len() {
                    return Err(model_err(format!(
                        "[measurements] joint_limits has {} pairs; the model has {} joints",
                        limits.len(),
                        spec.joint_kinds.len()
                    )));
                }
                let mut out = Vec::with_capacity(limits.len());
                for (d, ([lo, hi], kind)) in limits.iter().zip(&spec.joint_kinds).enumerate() {
                    let pair = format!("[measurements] joint_limits[{}] = [{}, {}]", d + 1, number(*lo), number(*hi));
                    if lo.is_nan() || hi.is_nan() || lo >= hi {
                        return Err(model_err(format!("{pair}: needs lo < hi")));
                    }
                    let f = if *kind == JointKind::Revolute { angle_unit.radians() } else { length_factor };
                    let (lo, hi) = (lo * f, hi * f);
                    // Within ±1e100 in the model's unit, as every value read (the ±1e100 rule).
                    if !(lo.abs() <= MAX_MAGNITUDE && hi.abs() <= MAX_MAGNITUDE) {
                        return Err(model_err(format!("{pair}: beyond ±{MAX_MAGNITUDE:e} in the model's unit")));
                    }
                    out.push([lo, hi]);
                }
                out
            }
        };
        let repeat_tolerance = match section.repeat_tolerance {
            Some(t) if !(t >= 0.0 && t * length_factor <= MAX_MAGNITUDE) => {
                return Err(model_err(format!(
                    "[measurements] repeat_tolerance = {}: needs a finite value in [0, {MAX_MAGNITUDE:e}]",
                    number(t)
                )));
            }
            t => t.map(|t| t * length_factor),
        };
        let joint_map = self.joint_map.clone();
        Ok(ColumnSpec {
            angle_unit,
            length_unit,
            min_rows: section.min_rows.unwrap_or(1),
            order: section.order.unwrap_or_default(),
            joint_limits,
            repeat_tolerance,
            joint_map,
            ..spec
        })
    }

    /// Column specification with the given column names (e.g. from the command line), in the
    /// model file's units.
    pub fn column_spec_with(&self, joints: Vec<String>, positions: Vec<String>) -> ColumnSpec {
        let kinds: Vec<JointKind> = (0..self.nominal.n_joints())
            .map(|d| if self.nominal.is_revolute(d) { JointKind::Revolute } else { JointKind::Prismatic })
            .collect();
        ColumnSpec {
            joint_columns: joints,
            position_columns: positions,
            joint_kinds: kinds.clone(),
            angle_unit: self.angle_unit,
            length_unit: self.length_unit,
            model_length_unit: self.length_unit,
            min_rows: 1,
            joint_limits: default_joint_limits(&kinds),
            repeat_tolerance: None,
            joint_map: None,
            planar_frame: self.planar_frame.clone(),
            tool_points: Vec::new(),
            order: crate::data::RowOrder::Measured,
            orientation_columns: None,
            range_hint: super::csv_import::RANGE_FROM_MODEL_FILE,
        }
    }
}

/// Reads and checks a model file (see the module documentation for the format).
pub fn load_model_file(path: impl AsRef<Path>) -> Result<ModelFile, ImportError> {
    let path = path.as_ref();
    let io = |message: String| ImportError::Io { file: path.to_path_buf(), message };
    let bytes = super::read_capped(path, super::MAX_MODEL_FILE_BYTES, "model file").map_err(|e| io(e.without_path()))?;
    let text = String::from_utf8(bytes).map_err(|e| io(format!("not UTF-8 text: {e}")))?;
    parse_model_file(&text, path)
}

/// Model files parsed by this process so far: a command parses its own once (issue 52;
/// `trainer/tests/end_to_end/model_parsed_once.rs` counts them).
pub fn parses() -> usize {
    PARSES.load(std::sync::atomic::Ordering::Relaxed)
}

static PARSES: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);

/// Parses model-file text; `path` names it in errors and anchors a relative URDF path.
pub fn parse_model_file(text: &str, path: &Path) -> Result<ModelFile, ImportError> {
    PARSES.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let file = path.to_path_buf();
    let raw: RawModelFile =
        toml::from_str(text).map_err(|e| ImportError::Toml { file: file.clone(), message: toml_error::toml_message(&e, text) })?;
    let model_err = |message: String| ImportError::Model { file: file.clone(), message };
    let _ = &raw.description;
    let deg = raw.angle_unit.radians();
    let given = raw.chain.is_some() as u8 + raw.urdf.is_some() as u8 + raw.planar.is_some() as u8;
    if given != 1 {
        return Err(model_err(format!("exactly one of [chain], [urdf] and [planar] must be given ({given} found)")));
    }
    let mut planar_frame = None;
    let urdf_base = raw.urdf.as_ref().and_then(|u| u.base.as_ref());
    if let Some(b) = urdf_base {
        if b.register != Some(true) || b.translation.is_some() || b.rpy.is_some() || b.rotation.is_some() {
            return Err(ImportError::Field {
                file: file.clone(),
                field: "[urdf.base]".into(),
                message: "a URDF chain's base is its base_link's frame; only `base = { register = true }` (data in a tracker's frame) may be given here".into(),
            });
        }
    }
    // Where the joint count comes from, for the messages of what must agree with it.
    let joint_source = match (&raw.chain, &raw.urdf) {
        (Some(_), _) => "[chain] joints",
        (_, Some(_)) => "[urdf] chain",
        _ => "[planar] lengths",
    };
    let register_base = raw.chain.as_ref().and_then(|c| c.base.as_ref()).or(urdf_base).is_some_and(|b| b.register == Some(true));
    let urdf = raw.urdf.as_ref().map(|u| UrdfSource {
        path: sections::urdf_path(u, path),
        base_link: u.base_link.clone(),
        tip_link: u.tip_link.clone(),
    });
    let (mut nominal, joint_names) = if let Some(chain) = raw.chain {
        sections::dh_chain(&chain, deg, path)?
    } else if let Some(u) = raw.urdf {
        sections::urdf_chain(&u, raw.length_unit, path)?
    } else {
        let planar = raw.planar.as_ref().expect("one section");
        planar_frame = sections::planar_frame(planar, deg, path)?;
        sections::planar(&planar.lengths, path)?
    };
    effects_section::apply(raw.gravity.as_ref(), &raw.effects, deg, &mut nominal).map_err(|e| ImportError::Field {
        file: file.clone(),
        field: e.field,
        message: e.message,
    })?;
    if let Some(m) = &raw.measurements {
        if m.joints.len() != nominal.n_joints() {
            return Err(model_err(format!(
                "[measurements] joints: names {} joint columns; the model has {} joints ({joint_source})",
                m.joints.len(),
                nominal.n_joints()
            )));
        }
        let points = nominal.tool_point_count();
        match &m.pose {
            Some(pose) => check_pose_section(m, pose, nominal.task_dim(), &file)?,
            None if m.positions.len() != nominal.task_dim() * points => {
                let per_point = if points > 1 { format!(" × {points} tool points") } else { String::new() };
                return Err(model_err(format!(
                    "[measurements] positions: names {} position columns; the task space has {} coordinates{per_point}",
                    m.positions.len(),
                    nominal.task_dim()
                )));
            }
            None => {}
        }
    }
    if let Some(m) = &raw.measurements {
        check_columns_distinct(m, &file)?;
    }
    if let Some((field, message)) = numbers::out_of_range(text) {
        return Err(ImportError::Field { file: file.clone(), field, message });
    }
    let joint_map = match raw.measurements.as_ref().and_then(|m| m.joint_map.as_ref()) {
        Some(map) => {
            let field_err = |(field, message)| ImportError::Field { file: file.clone(), field, message };
            let map = JointMap::new(map, &joint_names).map_err(field_err)?;
            let m = raw.measurements.as_ref().expect("the map is in [measurements]");
            map.check_range(&column_limits(m, &nominal, raw.angle_unit), &m.joints).map_err(field_err)?;
            Some(map)
        }
        None => None,
    };
    Ok(ModelFile {
        urdf,
        joint_map,
        planar_frame,
        register_base,
        path: file,
        name: raw.name,
        nominal,
        length_unit: raw.length_unit,
        angle_unit: raw.angle_unit,
        joint_names,
        measurements: raw.measurements,
    })
}

/// The joint limits in the columns' own units (the controller's values): declared, or the
/// default of one turn each way for revolute joints and none for prismatic ones.
fn column_limits(m: &MeasurementSection, nominal: &NominalModel, file_angle_unit: AngleUnit) -> Vec<[f64; 2]> {
    if let Some(limits) = &m.joint_limits {
        return limits.clone();
    }
    let turn = 2.0 * std::f64::consts::PI / m.angle_unit.unwrap_or(file_angle_unit).radians();
    (0..nominal.n_joints()).map(|d| if nominal.is_revolute(d) { [-turn, turn] } else { [f64::NEG_INFINITY, f64::INFINITY] }).collect()
}

/// No CSV column named twice in `[measurements]` (a joint twice, a position reusing a joint's
/// column, two points on one column set): each name reads one value per row.
fn check_columns_distinct(m: &MeasurementSection, file: &Path) -> Result<(), ImportError> {
    let empty = Vec::new();
    let pose = m.pose.as_ref();
    let lists: [(&str, &Vec<String>); 5] = [
        ("joints", &m.joints),
        ("positions", &m.positions),
        ("pose.position", pose.map_or(&empty, |p| &p.position)),
        ("pose.quaternion", pose.and_then(|p| p.quaternion.as_ref()).unwrap_or(&empty)),
        ("pose.rotation", pose.and_then(|p| p.rotation.as_ref()).unwrap_or(&empty)),
    ];
    let named: Vec<(String, &str)> = lists
        .iter()
        .flat_map(|(field, names)| names.iter().enumerate().map(move |(k, name)| (format!("{field}[{}]", k + 1), name.as_str())))
        .collect();
    for (k, (field, name)) in named.iter().enumerate() {
        if let Some((first, _)) = named[..k].iter().find(|(_, other)| other == name) {
            return Err(ImportError::Field {
                file: file.to_path_buf(),
                field: format!("[measurements] {field}"),
                message: format!("column '{}' is already {first}: each column holds one value", crate::error::excerpt(name)),
            });
        }
    }
    Ok(())
}

/// `[measurements] pose`: no `positions` beside it, 3 position columns, a quaternion (4) or a
/// rotation (9 columns), not both; a 3-D task space.
fn check_pose_section(m: &MeasurementSection, pose: &PoseSection, task_dim: usize, file: &Path) -> Result<(), ImportError> {
    let bad = |message: String| ImportError::Field { file: file.to_path_buf(), field: "[measurements] pose".into(), message };
    if !m.positions.is_empty() {
        return Err(bad("give either positions or pose, not both".into()));
    }
    if task_dim != 3 {
        return Err(bad(format!("a pose needs a 3-D task space; this model's has {task_dim} coordinates")));
    }
    if pose.position.len() != 3 {
        return Err(bad(format!("position names {} columns; a pose's position has 3", pose.position.len())));
    }
    match (&pose.quaternion, &pose.rotation) {
        (Some(_), Some(_)) => Err(bad("give either quaternion or rotation, not both".into())),
        (None, None) => Err(bad("needs quaternion = [\"qw\", \"qx\", \"qy\", \"qz\"] or rotation = [9 columns, row-major]".into())),
        (Some(q), None) if q.len() != 4 => Err(bad(format!("quaternion names {} columns; it has 4 (w, x, y, z)", q.len()))),
        (None, Some(r)) if r.len() != 9 => Err(bad(format!("rotation names {} columns; it has 9 (row-major)", r.len()))),
        _ => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use cbd_protocol::{DhConvention, Effect};
    use cbd_runtime::internals::kinematics::forward_kinematics;

    const SMALL: &str = r#"
length_unit = "m"
angle_unit = "rad"
[chain]
convention = "modified"
joints = [ { a = 0, alpha = 0, d = 0.1 }, { a = 0.3, alpha = 1.5707963267948966, d = 0, kind = "prismatic" } ]
base = { translation = [1, 2, 3], rotation = [[0, -1, 0], [1, 0, 0], [0, 0, 1]] }
tool = { translation = [0, 0, 0.05], rpy = [0.1, 0.2, 0.3] }
[measurements]
joints = ["q1", "q2"]
positions = ["x", "y", "z"]
length_unit = "mm"
"#;

    #[test]
    fn parses_a_modified_chain_with_units_and_columns() {
        let m = parse_model_file(SMALL, Path::new("small.toml")).unwrap();
        let NominalModel::DhChain(c) = &m.nominal else { panic!() };
        assert_eq!(c.convention, DhConvention::Modified);
        assert_eq!(c.joints[1].kind, JointKind::Prismatic);
        assert_eq!(c.base.translation, [1.0, 2.0, 3.0]);
        let spec = m.column_spec().unwrap();
        assert_eq!(spec.length_unit, LengthUnit::Mm);
        assert_eq!(spec.model_length_unit, LengthUnit::M);
        assert_eq!(spec.angle_unit, AngleUnit::Rad);
        // q = 0: p = base ∘ (Tz 0.1) ∘ (Tx 0.3 Rx 90°) ∘ tool.t — tool z (0.05) becomes −y, base turns x→y.
        let k = forward_kinematics(&m.nominal, &[0.0, 0.0]);
        let want = [1.0 + 0.05, 2.0 + 0.3, 3.0 + 0.1];
        for c in 0..3 {
            assert!((k.position[c] - want[c]).abs() < 1e-12, "{:?}", k.position);
        }
    }

    #[test]
    fn rows_are_in_measurement_order_unless_declared_unordered() {
        let spec = |text: &str| parse_model_file(text, Path::new("small.toml")).map(|m| m.column_spec().unwrap().order);
        assert_eq!(spec(SMALL).unwrap(), crate::data::RowOrder::Measured);
        let unordered = SMALL.replace("length_unit = \"mm\"", "length_unit = \"mm\"\norder = \"unordered\"");
        assert_eq!(spec(&unordered).unwrap(), crate::data::RowOrder::Unordered);
        let e = spec(&SMALL.replace("length_unit = \"mm\"", "length_unit = \"mm\"\norder = \"sorted\"")).unwrap_err().to_string();
        assert!(e.contains("small.toml") && e.contains("sorted") && e.contains("unordered"), "{e}");
    }

    #[test]
    fn unknown_field_is_an_error_naming_it() {
        let text = SMALL.replace("convention = \"modified\"", "convention = \"modified\"\nlink_lenght = 3");
        let e = parse_model_file(&text, Path::new("small.toml")).unwrap_err();
        let s = e.to_string();
        assert!(s.contains("link_lenght") && s.contains("small.toml"), "{s}");
        let e = parse_model_file(&SMALL.replace("\"mm\"", "\"inch\""), Path::new("small.toml")).unwrap_err();
        assert!(e.to_string().contains("inch"), "{e}");
    }

    #[test]
    fn inconsistent_files_are_rejected() {
        let bad = SMALL.replace("joints = [\"q1\", \"q2\"]", "joints = [\"q1\"]");
        assert!(parse_model_file(&bad, Path::new("x.toml")).unwrap_err().to_string().contains("joint columns"));
        let bad = SMALL.replace("[[0, -1, 0]", "[[0, -1, 0.5]");
        assert!(parse_model_file(&bad, Path::new("x.toml")).unwrap_err().to_string().contains("orthonormal"));
        let both = format!("{SMALL}\n[planar]\nlengths = [1.0]\n");
        assert!(parse_model_file(&both, Path::new("x.toml")).unwrap_err().to_string().contains("exactly one"));
    }

    const EFFECTS: &str = r#"
[gravity]
direction = [0, 0, -2]
link_masses = [2.5, 1]

[[effects]]
type = "gravity_compliance"
joint = 1
compliance = 0.01

[[effects]]
type = "encoder_scale"
joint = 2
scale = 1e-4

[[effects]]
type = "link_bending"
link = 2
compliance = 0.5
"#;

    #[test]
    fn effects_sections_are_read_in_the_files_units() {
        let m = parse_model_file(&format!("{SMALL}{EFFECTS}"), Path::new("fx.toml")).unwrap();
        let e = m.nominal.effects();
        assert_eq!(e.gravity.direction, [0.0, 0.0, -1.0]);
        assert_eq!(e.gravity.link_masses.as_slice(), &[2.5, 1.0]);
        assert_eq!(e.list.len(), 3);
        // Angles in the file's unit (rad here); joints 1-based in the file.
        assert_eq!(e.list[0], cbd_protocol::Effect::GravityCompliance { joint: 0, compliance: 0.01 });
        assert_eq!(e.list[2], cbd_protocol::Effect::LinkBending { link: 1, compliance: 0.5 });
    }

    #[test]
    fn written_model_files_read_back_to_the_same_model() {
        let deg_text = SMALL.replace("angle_unit = \"rad\"", "angle_unit = \"deg\"").replace("1.5707963267948966", "90");
        let deg_fx = EFFECTS
            .replace("type = \"encoder_scale\"", "type = \"transmission\"\nharmonic = 3\ncos = 0.2\nsin = -0.1")
            .replace("joint = 2\nscale = 1e-4", "joint = 1")
            + "\n[[effects]]\ntype = \"gravity_compliance\"\njoint = 2\ncompliance = 0.003\n";
        for text in [format!("{SMALL}{EFFECTS}"), format!("{deg_text}{deg_fx}"), format!("name = \"a \\\"b\\\"\"\n{SMALL}")] {
            let m = parse_model_file(&text, Path::new("in.toml")).unwrap();
            let written = write_model_file(&m, "written by a test\nsecond line");
            let back = parse_model_file(&written, Path::new("in.toml")).unwrap_or_else(|e| panic!("{e}\n{written}"));
            assert_eq!(back.name, m.name);
            assert_eq!(back.measurements, m.measurements);
            assert_eq!(back.nominal.effects().gravity, m.nominal.effects().gravity);
            // Degrees round-trip to within an ulp or two; positions agree to rounding.
            let q = [0.4, -0.02];
            let (a, b) = (forward_kinematics(&m.nominal, &q), forward_kinematics(&back.nominal, &q));
            for c in 0..3 {
                assert!((a.position[c] - b.position[c]).abs() < 1e-12, "{written}");
            }
            for (x, y) in m.nominal.effects().list.iter().zip(back.nominal.effects().list.iter()) {
                let close = |u: f64, v: f64| (u - v).abs() <= 1e-15 * u.abs().max(1e-300);
                let ok = match (x, y) {
                    (Effect::Transmission { cos: c1, sin: s1, .. }, Effect::Transmission { cos: c2, sin: s2, .. }) => {
                        close(*c1, *c2) && close(*s1, *s2)
                    }
                    (Effect::GravityCompliance { compliance: a, .. }, Effect::GravityCompliance { compliance: b, .. }) => close(*a, *b),
                    _ => x == y,
                };
                assert!(ok, "{x:?} vs {y:?}");
            }
            assert_eq!(back.nominal.effects().list.len(), m.nominal.effects().list.len());
            // A prismatic joint's compliance is a length per force: never converted as an angle.
            if text.contains("compliance = 0.003") {
                assert!(m.nominal.effects().list.contains(&Effect::GravityCompliance { joint: 1, compliance: 0.003 }));
            }
            // The written file is stable: writing what was read gives the same text.
            assert_eq!(write_model_file(&back, "written by a test\nsecond line"), written);
        }
    }

    #[test]
    fn bad_effects_are_errors_naming_entry_and_field() {
        let cases = [
            ("joint = 1\ncompliance = 0.01", "joint = 3\ncompliance = 0.01", "entry 1: joint = 3"),
            ("compliance = 0.01\n", "compliance = 0.01\nstiffness = 2\n", "stiffness"),
            ("type = \"link_bending\"", "type = \"wobble\"", "wobble"),
            ("scale = 1e-4", "scale = nan", "scale = NaN is not finite"),
            ("direction = [0, 0, -2]", "direction = [0, -2]", "[gravity] direction: 2 entries"),
            ("link_masses = [2.5, 1]", "link_masses = [2.5, -1]", "link_masses[2]: -1 is not a finite mass"),
            ("link = 2", "link = 0", "link = 0"),
            // Joint 2 of SMALL is prismatic: a transmission harmonic needs an angle.
            (
                "type = \"gravity_compliance\"\njoint = 1\ncompliance = 0.01",
                "type = \"transmission\"\njoint = 2\nharmonic = 1\ncos = 0\nsin = 0",
                "joint 2 is prismatic",
            ),
        ];
        for (from, to, needle) in cases {
            assert!(EFFECTS.contains(from), "{from}");
            let text = format!("{SMALL}{}", EFFECTS.replacen(from, to, 1));
            let e = parse_model_file(&text, Path::new("fx.toml")).unwrap_err().to_string();
            assert!(e.contains(needle) && e.contains("fx.toml"), "{needle}: {e}");
        }
    }

    /// Issue 17 item 7: lengths of 1e300 and `encoder_scale = 1e300` were accepted and the fit
    /// later failed with "the flow diverged … kernels too wide or σ too small". Now the model file
    /// is refused, naming the field.
    #[test]
    fn absurd_lengths_and_encoder_scale_name_the_field() {
        let bad = SMALL.replace("{ a = 0.3,", "{ a = 1e300,");
        let e = parse_model_file(&bad, Path::new("x.toml")).unwrap_err().to_string();
        assert!(e.contains("x.toml: [chain] joint 2: a = 1e300 is beyond"), "{e}");
        let bad = SMALL.replace("translation = [1, 2, 3]", "translation = [1, 2e300, 3]");
        let e = parse_model_file(&bad, Path::new("x.toml")).unwrap_err().to_string();
        assert!(e.contains("[chain.base]") && e.contains("2e300"), "{e}");
        let planar = "length_unit = \"m\"\nangle_unit = \"rad\"\n[planar]\nlengths = [1.0, 1e300]\n";
        let e = parse_model_file(planar, Path::new("p.toml")).unwrap_err().to_string();
        assert!(e.contains("p.toml: [planar] lengths[2] = 1e300 is beyond"), "{e}");
        let text = format!("{SMALL}{}", EFFECTS.replacen("scale = 1e-4", "scale = 1e300", 1));
        let e = parse_model_file(&text, Path::new("fx.toml")).unwrap_err().to_string();
        assert!(e.contains("fx.toml: [[effects]] entry 2: scale = 1e300"), "{e}");
        let text = format!("{SMALL}{}", EFFECTS.replacen("compliance = 0.5", "compliance = 1e200", 1));
        let e = parse_model_file(&text, Path::new("fx.toml")).unwrap_err().to_string();
        assert!(e.contains("entry 3: compliance = 1e200 is beyond"), "{e}");
    }

    /// Issue 26 item 6: `[planar]` holds base, yaw and joint offsets (the file's units), reads
    /// rows into the chain's frame and writes them back; bad entries name the field.
    #[test]
    fn planar_frame_reads_rows_into_the_chain_frame_and_round_trips() {
        let text = "length_unit = \"mm\"\nangle_unit = \"deg\"\n[planar]\nlengths = [1000.0, 500.0]\nbase = [30.0, -20.0]\nyaw = 90.0\noffsets = [1.0, -2.0]\n\
                    [measurements]\njoints = [\"q1\", \"q2\"]\npositions = [\"x\", \"y\"]\n";
        let m = parse_model_file(text, Path::new("p.toml")).unwrap();
        let frame = m.planar_frame.clone().unwrap();
        assert_eq!(frame.base, [30.0, -20.0]);
        let deg = AngleUnit::Deg.radians();
        assert_eq!((frame.yaw, frame.offsets.clone()), (90.0 * deg, vec![1.0 * deg, -2.0 * deg]));
        let rows = crate::data::csv_import::read_measurements_from(
            "q1,q2,x,y\n10,20,30,-10\n".as_bytes(),
            Path::new("d.csv"),
            &m.column_spec().unwrap(),
        )
        .unwrap()
        .measurements;
        // Joints + offsets; (30, −10) − base = (0, 10) turned by −90°: (10, 0).
        assert_eq!(rows.joints, vec![11.0 * deg, 18.0 * deg]);
        assert!((rows.positions[0] - 10.0).abs() < 1e-12 && rows.positions[1].abs() < 1e-12, "{:?}", rows.positions);
        let written = write_model_file(&m, "h");
        let back = parse_model_file(&written, Path::new("p.toml")).unwrap();
        assert_eq!(back.planar_frame.as_ref().map(|f| f.base), Some(frame.base));
        assert_eq!(write_model_file(&back, "h"), written);
        let bad = text.replace("offsets = [1.0, -2.0]", "offsets = [1.0]");
        let e = parse_model_file(&bad, Path::new("p.toml")).unwrap_err().to_string();
        assert!(e.contains("p.toml: [planar] offsets: 1 entries; the arm has 2 joints"), "{e}");
        let bad = text.replace("yaw = 90.0", "yaw = nan");
        assert!(parse_model_file(&bad, Path::new("p.toml")).unwrap_err().to_string().contains("[planar] yaw: NaN"));
        // Composition: a frame given in another's chain coordinates.
        let inner = crate::nominal::planar::PlanarFrame { offsets: vec![0.1, 0.2], base: [1.0, 0.0], yaw: 0.3 };
        let total = frame.then(&inner);
        let p = [0.7, -0.4];
        let (a, b) = (total.from_chain(&p), frame.from_chain(&inner.from_chain(&p)));
        assert!((a[0] - b[0]).abs() < 1e-12 && (a[1] - b[1]).abs() < 1e-12, "{a:?} {b:?}");
    }

    /// Issue 26 item 2: `base = { register = true }` reads as the identity with the flag, writes
    /// back as itself; with a pose, on the tool or `false` it is an error naming the field.
    #[test]
    fn an_unknown_base_round_trips_and_bad_uses_name_the_field() {
        let base = "base = { translation = [1, 2, 3], rotation = [[0, -1, 0], [1, 0, 0], [0, 0, 1]] }";
        let text = SMALL.replace(base, "base = { register = true }");
        let m = parse_model_file(&text, Path::new("r.toml")).unwrap();
        let NominalModel::DhChain(c) = &m.nominal else { panic!() };
        assert!(m.register_base && c.base == cbd_protocol::Transform::IDENTITY);
        let written = write_model_file(&m, "h");
        assert!(written.contains("base = { register = true }"), "{written}");
        assert!(parse_model_file(&written, Path::new("r.toml")).unwrap().register_base);
        assert!(!parse_model_file(SMALL, Path::new("r.toml")).unwrap().register_base);
        for (bad, needle) in [
            ("base = { register = true, translation = [1, 2, 3] }", "[chain.base]: give either register = true or the base's pose"),
            ("base = { register = false }", "[chain.base]: register = false"),
        ] {
            let e = parse_model_file(&SMALL.replace(base, bad), Path::new("r.toml")).unwrap_err().to_string();
            assert!(e.contains(needle), "{e}");
        }
        let e = parse_model_file(&SMALL.replace("tool = {", "tool = { register = true,"), Path::new("r.toml")).unwrap_err().to_string();
        assert!(e.contains("[chain.tool]: register applies to the base only"), "{e}");
    }

    /// Issue 26 item 1: tool points and their columns, or a measured pose read as the points
    /// (y_j = p + R p_j); one row per (pose, point), pose-major; written back as read; bad
    /// sections name the field, bad rows the file, line and columns.
    #[test]
    fn tool_points_and_poses_read_as_point_rows_and_round_trip() {
        let points = SMALL
            .replace(
                "tool = { translation = [0, 0, 0.05], rpy = [0.1, 0.2, 0.3] }",
                "tool = { translation = [0, 0, 0.05], points = [[0, 0, 0], [0.1, 0, 0], [0, 0.2, 0]] }",
            )
            .replace(
                "positions = [\"x\", \"y\", \"z\"]",
                "positions = [\"x1\", \"y1\", \"z1\", \"x2\", \"y2\", \"z2\", \"x3\", \"y3\", \"z3\"]",
            );
        let m = parse_model_file(&points, Path::new("p.toml")).unwrap();
        assert_eq!(m.nominal.tool_points(), &[[0.0, 0.0, 0.0], [0.1, 0.0, 0.0], [0.0, 0.2, 0.0]]);
        let back = parse_model_file(&write_model_file(&m, "h"), Path::new("p.toml")).unwrap();
        assert_eq!((&back.nominal, &back.measurements), (&m.nominal, &m.measurements));
        let csv = "q1,q2,x1,y1,z1,x2,y2,z2,x3,y3,z3\n0.1,0.2,1,2,3,101,2,3,1,202,3\n0.3,0.4,4,5,6,104,5,6,4,205,6\n";
        let read = |spec: &ColumnSpec, csv: &str| crate::data::csv_import::read_measurements_from(csv.as_bytes(), Path::new("t.csv"), spec);
        let data = read(&m.column_spec().unwrap(), csv).unwrap().measurements;
        assert_eq!((data.len(), data.pose_count(), data.points_per_pose, data.task_dim), (6, 2, 3, 3));
        // q2 is prismatic (mm columns, m model), as are the positions.
        assert_eq!(data.joints(4), data.joints(3));
        assert!(data.position(4).iter().zip([0.104, 0.005, 0.006]).all(|(a, b)| (a - b).abs() < 1e-15), "{:?}", data.position(4));
        // The pose (p, q) of a rotation of 90° about z: point 2 (0.1, 0, 0) lands at p + (0, 0.1, 0).
        let pose = points.replace(
            "positions = [\"x1\", \"y1\", \"z1\", \"x2\", \"y2\", \"z2\", \"x3\", \"y3\", \"z3\"]",
            "pose = { position = [\"x\", \"y\", \"z\"], quaternion = [\"qw\", \"qx\", \"qy\", \"qz\"] }",
        );
        let m = parse_model_file(&pose, Path::new("q.toml")).unwrap();
        let back = parse_model_file(&write_model_file(&m, "h"), Path::new("q.toml")).unwrap();
        assert_eq!(back.measurements, m.measurements);
        let h = std::f64::consts::FRAC_1_SQRT_2;
        let csv = format!("q1,q2,x,y,z,qw,qx,qy,qz\n0.1,0.2,1000,2000,3000,{h},0,0,{h}\n");
        let data = read(&m.column_spec().unwrap(), &csv).unwrap().measurements;
        assert_eq!(data.len(), 3);
        for (row, want) in [(0, [1.0, 2.0, 3.0]), (1, [1.0, 2.1, 3.0]), (2, [0.8, 2.0, 3.0])] {
            assert!(data.position(row).iter().zip(want).all(|(a, b)| (a - b).abs() < 1e-15), "{row}: {:?}", data.position(row));
        }
        let e = read(&m.column_spec().unwrap(), "q1,q2,x,y,z,qw,qx,qy,qz\n0.1,0.2,1,2,3,0.9,0,0,0\n").unwrap_err().to_string();
        assert!(e.starts_with("t.csv:2: column 'qw,qx,qy,qz'") && e.contains("norm is 0.900000"), "{e}");
        for (from, to, needle) in [
            ("points = [[0, 0, 0],", "points = [[0, 0, 0], [0, 0, 0],", "[chain.tool] points: points 1 and 2 are the same point"),
            ("quaternion = [\"qw\", \"qx\", \"qy\", \"qz\"]", "quaternion = [\"qw\"]", "[measurements] pose: quaternion names 1 columns"),
            ("quaternion = [", "rotation = [\"r\"], quaternion = [", "[measurements] pose: give either quaternion or rotation"),
            (
                "base = { translation = [1, 2, 3],",
                "base = { points = [[1, 2, 3]], translation = [1, 2, 3],",
                "[chain.base]: points belong to the tool",
            ),
        ] {
            let e = parse_model_file(&pose.replace(from, to), Path::new("q.toml")).unwrap_err().to_string();
            assert!(e.contains(needle), "{e}");
        }
        let e = parse_model_file(&points.replace("\"z3\"]", "]"), Path::new("p.toml")).unwrap_err().to_string();
        assert!(e.contains("names 8 position columns; the task space has 3 coordinates × 3 tool points"), "{e}");
    }

    /// Issue 39 cases 5, 9, 10: arrays one entry too long (NaN or not), limits beyond ±1e100 and a
    /// column named twice were read; each is an error naming the field.
    #[test]
    fn arrays_are_read_exactly_values_bounded_and_columns_distinct() {
        let cases = [
            (
                "translation = [0, 0, 0.05]",
                "translation = [0, 0, 0.05, 99]",
                "([chain] tool.translation): invalid length 4, expected an array of exactly 3",
            ),
            ("translation = [0, 0, 0.05]", "translation = [0, 0, 0.05, nan]", "invalid length 4"),
            ("rpy = [0.1, 0.2, 0.3]", "rpy = [0.1, 0.2, 0.3, 4]", "([chain] tool.rpy): invalid length 4"),
            ("[0, 0, 1]] }", "[0, 0, 1], [0, 0, 0]] }", "([chain] base.rotation): invalid length 4"),
            ("[1, 0, 0], [0, 0, 1]] }", "[1, 0, 0, 0], [0, 0, 1]] }", "([chain] base.rotation): invalid length 4"),
            (
                "length_unit = \"mm\"",
                "length_unit = \"mm\"\njoint_limits = [[-1, 1], [-1, 1, 3]]",
                "([measurements] joint_limits): invalid length 3",
            ),
            (
                "length_unit = \"mm\"",
                "length_unit = \"mm\"\njoint_limits = [[-1e300, 1e300], [-1, 1]]",
                "[measurements] joint_limits[1][1]: -1e300 is beyond ±1e100",
            ),
            (
                "positions = [\"x\", \"y\", \"z\"]",
                "positions = [\"x\", \"q2\", \"z\"]",
                "[measurements] positions[2]: column 'q2' is already joints[2]",
            ),
            ("joints = [\"q1\", \"q2\"]", "joints = [\"q1\", \"q1\"]", "[measurements] joints[2]: column 'q1' is already joints[1]"),
            (
                "length_unit = \"mm\"",
                "length_unit = \"mm\"\nrepeat_tolerance = 1e300",
                "[measurements] repeat_tolerance: 1e300 is beyond ±1e100",
            ),
        ];
        for (from, to, needle) in cases {
            assert!(SMALL.contains(from), "{from}");
            let e = parse_model_file(&SMALL.replacen(from, to, 1), Path::new("x.toml")).unwrap_err().to_string();
            assert!(e.starts_with("x.toml: ") && e.contains(needle), "{to}: {e}");
        }
        let planar = "length_unit = \"m\"\nangle_unit = \"rad\"\n[planar]\nlengths = [1.0, 0.5]\nbase = [0.1, 0.2, nan]\n";
        let e = parse_model_file(planar, Path::new("p.toml")).unwrap_err().to_string();
        assert!(e.contains("([planar] base): invalid length 3"), "{e}");
        // Limits within ±1e100 in the file's unit that convert beyond it (m columns, µm model).
        let um = SMALL
            .replace("length_unit = \"m\"", "length_unit = \"um\"")
            .replace("length_unit = \"mm\"", "length_unit = \"m\"\njoint_limits = [[-1, 1], [-1e99, 1e99]]");
        let e = parse_model_file(&um, Path::new("u.toml")).unwrap().column_spec().unwrap_err().to_string();
        assert!(e.contains("joint_limits[2] = [-1e99, 1e99]: beyond ±1e100 in the model's unit"), "{e}");
    }

    /// A rotation typed with seven digits (orthonormal within the file's 1e-6) becomes the nearest
    /// rotation, which the runtime's loader accepts (1e-9); an exact one keeps its bits.
    #[test]
    fn rotations_of_printed_digits_are_made_orthonormal() {
        let h = "0.7071068";
        let text = SMALL.replace("[[0, -1, 0], [1, 0, 0], [0, 0, 1]]", &format!("[[{h}, -{h}, 0], [{h}, {h}, 0], [0, 0, 1]]"));
        let m = parse_model_file(&text, Path::new("r.toml")).unwrap();
        let NominalModel::DhChain(c) = &m.nominal else { panic!() };
        let r = c.base.rotation;
        for i in 0..3 {
            for j in 0..3 {
                let dot: f64 = (0..3).map(|k| r[3 * i + k] * r[3 * j + k]).sum();
                assert!((dot - f64::from(u8::from(i == j))).abs() < 1e-15, "{r:?}");
            }
        }
        assert!((r[0] - std::f64::consts::FRAC_1_SQRT_2).abs() < 1e-15);
        let exact = parse_model_file(SMALL, Path::new("r.toml")).unwrap();
        let NominalModel::DhChain(c) = &exact.nominal else { panic!() };
        assert_eq!(c.base.rotation, [0.0, -1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0]);
    }

    #[test]
    fn urdf_model_file_loads_relative_to_itself() {
        let dir = std::env::temp_dir().join(format!("cbd-model-file-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join("arm.urdf"), crate::nominal::urdf::tests_support::TEST_URDF).unwrap();
        std::fs::write(
            dir.join("arm.toml"),
            "length_unit = \"mm\"\nangle_unit = \"deg\"\n[urdf]\npath = \"arm.urdf\"\nbase_link = \"world\"\ntip_link = \"tool0\"\n",
        )
        .unwrap();
        let m = load_model_file(dir.join("arm.toml")).unwrap();
        assert_eq!(m.joint_names.len(), 6);
        let robot = urdf_rs::read_from_string(crate::nominal::urdf::tests_support::TEST_URDF).unwrap();
        let q = [0.1, 0.2, -0.3, 0.0, 0.5, 0.6];
        let reference = crate::nominal::urdf::urdf_tip_pose(&robot, "world", "tool0", &q, 1000.0).unwrap();
        let k = forward_kinematics(&m.nominal, &q);
        for c in 0..3 {
            assert!((k.position[c] - reference.translation()[c]).abs() < 1e-9);
        }
        assert!(!m.register_base);
        // A tracker's frame: `[urdf] base = { register = true }`; no other base may be given there.
        let urdf = "length_unit = \"mm\"\nangle_unit = \"deg\"\n[urdf]\npath = \"arm.urdf\"\nbase_link = \"world\"\ntip_link = \"tool0\"\n";
        std::fs::write(dir.join("tracker.toml"), format!("{urdf}base = {{ register = true }}\n")).unwrap();
        let tracker = load_model_file(dir.join("tracker.toml")).unwrap();
        assert!(tracker.register_base && tracker.nominal == m.nominal);
        for bad in ["base = { register = false }", "base = { register = true, translation = [1, 2, 3] }", "base = { rpy = [0, 0, 1] }"] {
            std::fs::write(dir.join("bad.toml"), format!("{urdf}{bad}\n")).unwrap();
            let e = load_model_file(dir.join("bad.toml")).unwrap_err().to_string();
            assert!(e.contains("bad.toml") && e.contains("[urdf.base]") && e.contains("only `base = { register = true }`"), "{e}");
        }
        // Issue 39 case 8: a joint map keyed by the URDF's joint names, written as the DH table
        // (joints q1 … q6), read back naming the same joints.
        let mapped = format!(
            "{urdf}[measurements]\njoints = [\"a\", \"b\", \"c\", \"d\", \"e\", \"f\"]\npositions = [\"x\", \"y\", \"z\"]\n\
             [measurements.joint_map]\nsign = {{ j2 = -1 }}\nscale = {{ slide = 2.0 }}\noffset = {{ j6 = 5.0 }}\n"
        );
        std::fs::write(dir.join("mapped.toml"), mapped).unwrap();
        let m = load_model_file(dir.join("mapped.toml")).unwrap();
        let written = write_model_file(&m, "h");
        assert!(
            written.contains("sign = { \"q2\" = -1.0 }") && written.contains("\"q4\" = 2.0") && written.contains("\"q6\" = 5.0"),
            "{written}"
        );
        std::fs::write(dir.join("written.toml"), &written).unwrap();
        let back = load_model_file(dir.join("written.toml")).unwrap();
        assert_eq!(back.joint_map, m.joint_map);
        std::fs::remove_dir_all(&dir).ok();
    }
}

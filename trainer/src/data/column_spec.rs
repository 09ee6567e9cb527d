//! Which CSV columns hold what, and in which units: what a model file's `[measurements]` (or the
//! built-in arm) tells the importer (`csv_import`) and the commands that write joint columns back
//! (`joint_columns`).

use super::joint_map::JointMap;
use super::units::{AngleUnit, LengthUnit};
use crate::nominal::planar::PlanarFrame;
use cbd_protocol::JointKind;

/// Which columns hold what, and in which units.
#[derive(Debug, Clone, PartialEq)]
pub struct ColumnSpec {
    /// One column per joint, in chain order.
    pub joint_columns: Vec<String>,
    /// One column per task coordinate.
    pub position_columns: Vec<String>,
    /// Kind of each joint: revolute columns are in `angle_unit`, prismatic ones in `length_unit`.
    pub joint_kinds: Vec<JointKind>,
    /// Unit of the revolute joint columns in the file (converted to radians).
    pub angle_unit: AngleUnit,
    /// Unit of the position (and prismatic joint) columns in the file.
    pub length_unit: LengthUnit,
    /// The model's length unit, which lengths are converted to.
    pub model_length_unit: LengthUnit,
    /// Fewer data rows is an error.
    pub min_rows: usize,
    /// Allowed range of each joint, model units (radians or the model's length unit); a value
    /// outside is an error. [`default_joint_limits`] when the model file declares none.
    pub joint_limits: Vec<[f64; 2]>,
    /// Largest distance, model length unit, between the positions of two rows with the same joint
    /// configuration before they count as contradictory (an error). `None`: 1e-3 of the diagonal
    /// of the positions' bounding box.
    pub repeat_tolerance: Option<f64>,
    /// Controller joint values (the columns, in their units) → model joints, applied before the
    /// unit conversion (`[measurements.joint_map]`); `None`: the columns are the model's joints.
    pub joint_map: Option<JointMap>,
    /// A `[planar]` arm's base, yaw and joint offsets: rows are read into its chain's frame
    /// (joints + offsets, positions R(−yaw)(y − base)) after the units and the joint map.
    pub planar_frame: Option<PlanarFrame>,
    /// The model's tool points (offsets in the tool frame, model length unit): each file row is a
    /// pose and becomes one data row per point (pose-major, `Measurements::points_per_pose`).
    /// Empty: one point, today's rows. Without `orientation_columns`, `position_columns` holds
    /// each point's coordinates in turn (x1, y1, z1, x2, …).
    pub tool_points: Vec<[f64; 3]>,
    /// A measured pose's orientation: `position_columns` is then the tool origin and the rows are
    /// the points y_j = p + R p_j.
    pub orientation_columns: Option<OrientationColumns>,
    /// Whether the file's rows are in measurement order ([`super::RowOrder`]; `[measurements] order`).
    pub order: super::RowOrder,
    /// How the joints' range can be changed, for a joint value outside it: a model file's
    /// [`RANGE_FROM_MODEL_FILE`], or what applies where there is none.
    pub range_hint: &'static str,
}

/// [`ColumnSpec::range_hint`] of a model file's columns.
pub const RANGE_FROM_MODEL_FILE: &str = "declare `joint_limits` in [measurements] to change the range";

/// The orientation columns of a measured pose.
#[derive(Debug, Clone, PartialEq)]
pub enum OrientationColumns {
    /// A unit quaternion (w, x, y, z).
    Quaternion(Vec<String>),
    /// A rotation matrix, row-major.
    Rotation(Vec<String>),
}

impl OrientationColumns {
    pub(super) fn names(&self) -> &[String] {
        match self {
            OrientationColumns::Quaternion(v) | OrientationColumns::Rotation(v) => v,
        }
    }
}

/// One full turn each way for revolute joints (beyond that no arm we know of turns, and a larger
/// value is a unit or column mistake); no limit for prismatic joints.
pub fn default_joint_limits(kinds: &[JointKind]) -> Vec<[f64; 2]> {
    let turn = 2.0 * std::f64::consts::PI;
    kinds.iter().map(|k| if *k == JointKind::Revolute { [-turn, turn] } else { [f64::NEG_INFINITY, f64::INFINITY] }).collect()
}

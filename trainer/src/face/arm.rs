//! The arm a calibration works on, parsed once: its nominal model and how its measurements read.

use crate::error::{Context, Result};

/// The arm a command works on, read once (issue 52: one parse of the model file per command): the
/// model file as parsed — or the built-in RR arm — with its nominal model and how to read its
/// measurement CSV files. A front (the `cbd` command, the Python package) builds it from the file it
/// parsed and takes everything else it needs from it (units, `register = true`), never from the file again.
#[derive(Debug, Clone)]
pub struct ArmModel {
    /// The model file's path as given (`None`: the built-in arm); messages name it.
    pub path: Option<std::path::PathBuf>,
    /// The parsed model file (`None`: the built-in arm).
    pub file: Option<crate::data::model_file::ModelFile>,
    pub nominal: cbd_protocol::NominalModel,
    pub spec: crate::data::csv_import::ColumnSpec,
}

impl ArmModel {
    /// A model file already parsed, read from `path`.
    pub fn from_file(path: &std::path::Path, file: crate::data::model_file::ModelFile) -> Result<ArmModel> {
        let spec = file.column_spec()?;
        Ok(ArmModel { path: Some(path.to_path_buf()), nominal: file.nominal.clone(), spec, file: Some(file) })
    }

    /// The paper's planar RR arm (columns q1, q2 in radians, x, y in metres; rows unordered).
    pub fn builtin_rr() -> ArmModel {
        use crate::data::model_file::{AngleUnit, LengthUnit};
        ArmModel {
            path: None,
            file: None,
            nominal: crate::simulate::rr::nominal(),
            spec: crate::data::csv_import::ColumnSpec {
                joint_columns: vec!["q1".into(), "q2".into()],
                position_columns: vec!["x".into(), "y".into()],
                joint_kinds: vec![cbd_protocol::JointKind::Revolute; 2],
                angle_unit: AngleUnit::Rad,
                length_unit: LengthUnit::M,
                model_length_unit: LengthUnit::M,
                min_rows: 2,
                joint_limits: crate::data::csv_import::default_joint_limits(&[cbd_protocol::JointKind::Revolute; 2]),
                repeat_tolerance: None,
                joint_map: None,
                planar_frame: None,
                tool_points: Vec::new(),
                orientation_columns: None,
                // The paper's benchmark is a grid: its rows carry no time order.
                order: crate::data::RowOrder::Unordered,
                range_hint:
                    "the built-in arm's joints are read within one turn each way; a model file (--model) may declare `joint_limits`",
            },
        }
    }

    /// Whether the model file declares its base unknown (`base = { register = true }`): the
    /// nominal is then in the frame registered on the training data.
    pub fn register_base(&self) -> bool {
        self.file.as_ref().is_some_and(|f| f.register_base)
    }

    /// The model's length unit's name (the data are read into it).
    pub fn length_unit(&self) -> &'static str {
        self.spec.model_length_unit.name()
    }

    /// The model file's name for messages, or "the built-in RR arm".
    pub fn name(&self) -> String {
        self.path.as_ref().map_or("the built-in RR arm".to_string(), |p| p.display().to_string())
    }
}

/// Registers the nominal's base on the training `data` when `arm`'s model file declares it unknown
/// (`[chain] base = { register = true }`), and says so on stderr: from here on "nominal" is the
/// nominal in the registered frame.
pub fn register_base_if_unknown(
    arm: &ArmModel,
    nominal: &mut cbd_protocol::NominalModel,
    data: &crate::data::Measurements,
    data_path: &std::path::Path,
) -> Result<Option<crate::parametric::base_registration::Registration>> {
    if !arm.register_base() {
        return Ok(None);
    }
    let r = crate::parametric::base_registration::register_and_refine(nominal, data).context(data_path.display())?;
    errln!("{}: {}", data_path.display(), r.describe(arm.length_unit()));
    Ok(Some(r))
}

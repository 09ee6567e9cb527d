//! The library's face (issue 52): a calibration's operations on parsed values, returning values. A
//! front — the `cbd` command, the Python package, a program — reads its files or arrays once, makes
//! them an [`ArmModel`] and a [`Dataset`], and calls these; nothing here reads or writes a file or
//! prints to stdout. Warnings and what the pipeline chose go to the crate's message channel
//! (`errln!`, which a program redirects with [`set_message_sink`]), as every stage's do.
//!
//! Besides the operations (one file each), what a front needs around them: [`run`] (the worker
//! pool and staged outputs a command runs in), [`Dataset::read`] and [`Dataset::from_rows`] (its
//! measurements from a CSV file or from arrays), [`read_blob`], and the types its inputs are made
//! of, re-exported here so that a front imports the face alone.

pub use crate::error::{Error, Result};

mod arm;
pub(crate) mod blob_rows;
mod check;
mod compare;
mod compensate;
mod diagnose;
mod evaluate;
mod export;
mod fit;
pub mod peers;
mod plan;
mod plan_check;
mod settings;
mod simulate;

pub(crate) use arm::register_base_if_unknown;
pub use arm::ArmModel;
pub use check::{check, CheckSettings, Checked, EXTRAPOLATION_THRESHOLD};
pub use compare::{compare, CompareSettings, Comparison};
pub use compensate::{compensate, CompensatedCommand, MAX_ITERATIONS};
pub use diagnose::{diagnose, DiagnoseSettings, Diagnosis};
pub use evaluate::{evaluate, DecodedBlob, Evaluation};
pub use export::{export, ExportTargets, ExportedGeometry};
pub use fit::{fit, print_calibration, Calibration, FitSettings};
pub use plan::{candidates_spec, check_plannable, plan, Plan, PlanSettings};
pub use plan_check::{plan_check, CheckPlan, CheckPlanSettings};
pub use settings::PipelineOptions;
pub use simulate::{poses_spec, simulate, SimulateSettings, Simulated};

// What a front's inputs and outputs are made of: the model file and its columns, the message
// channel, the output files (written atomically, checked against the inputs) and the memory check.
pub use crate::data::csv_import::{ColumnSpec, OrientationColumns};
pub use crate::data::joint_columns::JointColumns;
pub use crate::data::model_file::{load_model_file, ModelFile};
pub use crate::evaluation::blob_match::check_blob_fits_model_file;
pub use crate::evaluation::compensation::CompensateError;
pub use crate::io::{check_output_dir, check_paths, set_message_sink, write_atomically, MessageSink, Stream};
pub use crate::memory::{room_for, MemoryError};
pub use crate::predict::check_calibrator;

/// Runs one command as the `cbd` binary runs it: on a worker pool as large as the memory allows (at
/// most two), its outputs staged (they reach their paths only if it succeeds), the record of the
/// files a run reads started afresh.
pub fn run<T: Send>(work: impl FnOnce() -> Result<T> + Send) -> Result<T> {
    crate::io::forget_inputs();
    let threads = crate::memory::workers_for_memory(crate::memory::available_bytes());
    crate::memory::run_in_pool(threads, || crate::io::with_staged_outputs(work))?
}

/// The bytes of the blob file at `path` (refused beyond the largest blob the format allows).
pub fn read_blob(path: &std::path::Path) -> Result<Vec<u8>> {
    crate::data::read_capped(path, crate::data::MAX_BLOB_BYTES, "blob")
}

/// `bytes` (the blob `source` names in messages) decoded and checked to fit `nominal`, the model
/// file's chain (joints and their kinds, task coordinates, tool points, length unit), and its import
/// `spec` (the frame rows are read into, where the blob records it); a misfit names the blob and
/// `model_file` (`None`: the built-in RR arm).
pub fn decode_blob<'b>(
    bytes: &'b [u8],
    source: &std::path::Path,
    model_file: Option<&std::path::Path>,
    nominal: &cbd_protocol::NominalModel,
    spec: &ColumnSpec,
) -> Result<cbd_protocol::Model<'b>> {
    use crate::error::Context;
    let decoded = cbd_protocol::decode(bytes).context(source.display())?;
    check_blob_fits_model_file(&decoded, nominal, spec).map_err(|why| {
        let file = model_file.map_or("the built-in RR arm (no --model given)".to_string(), |p| p.display().to_string());
        Error::InvalidInput(format!("{}: does not fit {file}: {why}", source.display()))
    })?;
    Ok(decoded)
}

/// Measurements as a front read them, with what messages call them.
pub struct Dataset {
    /// The rows' source in messages: the CSV file's path, or the arrays' label (`(q, y)`).
    pub source: std::path::PathBuf,
    pub imported: crate::data::csv_import::ImportedMeasurements,
}

impl Dataset {
    /// The measurements of the CSV file at `path`, read with `spec`'s columns (a front's one read of it).
    pub fn read(path: &std::path::Path, spec: &ColumnSpec) -> Result<Dataset> {
        let imported = crate::data::csv_import::read_measurements(path, spec)?;
        Ok(Dataset { source: path.to_path_buf(), imported })
    }

    /// Measurements from arrays in `spec`'s columns — `q` the joint columns and `y` the position
    /// (and orientation) columns, `rows` rows of each, row-major — through the CSV import's own
    /// conversion and checks, no text between them; `source` names them in messages (`(q, y) row 3: …`).
    pub fn from_rows(source: &str, spec: &ColumnSpec, q: &[f64], y: &[f64], rows: usize) -> Result<Dataset> {
        let imported = crate::data::csv_import::measurements_from_rows(source, q, y, rows, spec)?;
        Ok(Dataset { source: source.into(), imported })
    }
}

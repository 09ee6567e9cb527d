//! The library's face (issue 52): a calibration's operations on parsed values, returning values. A
//! front — the `cbd` command, the Python package, a program — reads its files or arrays once, makes
//! them an [`ArmModel`] and a [`Dataset`], and calls these; nothing here reads or writes a file or
//! prints to stdout. Warnings and what the pipeline chose go to the crate's message channel
//! (`errln!`, which a program redirects with `crate::io::set_message_sink`), as every stage's do.

use crate::error::Result;

mod arm;
pub(crate) mod blob_rows;
mod compare;
mod diagnose;
mod evaluate;
mod export;
mod fit;
pub mod peers;
mod plan;
mod settings;
mod simulate;

pub use arm::{register_base_if_unknown, ArmModel};
pub use compare::{compare, CompareSettings, Comparison};
pub use diagnose::{diagnose, DiagnoseSettings, Diagnosis};
pub use evaluate::{evaluate, DecodedBlob, Evaluation};
pub use export::{export, ExportTargets, ExportedGeometry};
pub use fit::{fit, print_calibration, Calibration, FitSettings};
pub use plan::{candidates_spec, check_plannable, plan, Plan, PlanSettings};
pub use settings::PipelineOptions;
pub use simulate::{poses_spec, simulate, SimulateSettings, Simulated};

/// Measurements as a front read them, with what messages call them.
pub struct Dataset {
    /// The rows' source in messages: the CSV file's path, or the arrays' label (`(q, y)`).
    pub source: std::path::PathBuf,
    pub imported: crate::data::csv_import::ImportedMeasurements,
}

impl Dataset {
    /// The measurements of the CSV file at `path`, read with `spec`'s columns (a front's one read of it).
    pub fn read(path: &std::path::Path, spec: &crate::data::csv_import::ColumnSpec) -> Result<Dataset> {
        let imported = crate::data::csv_import::read_measurements(path, spec)?;
        Ok(Dataset { source: path.to_path_buf(), imported })
    }
}

//! The library's face (issue 52): a calibration's operations on parsed values, returning values. A
//! front — the `cbd` command, the Python package, a program — reads its files or arrays once, makes
//! them an [`ArmModel`] and a [`Dataset`], and calls these; nothing here reads or writes a file or
//! prints to stdout. Warnings and what the pipeline chose go to the crate's message channel
//! (`errln!`, which a program redirects with `crate::io::set_message_sink`), as every stage's do.

mod arm;
pub(crate) mod blob_rows;
mod evaluate;
mod fit;
mod settings;

pub use arm::{register_base_if_unknown, ArmModel};
pub use evaluate::{evaluate, DecodedBlob, Evaluation};
pub use fit::{fit, print_calibration, Calibration, FitSettings};
pub use settings::PipelineOptions;

/// Measurements as a front read them, with what messages call them.
pub struct Dataset {
    /// The rows' source in messages: the CSV file's path, or the arrays' label (`(q, y)`).
    pub source: std::path::PathBuf,
    pub imported: crate::data::csv_import::ImportedMeasurements,
}

//! What several commands share: their argument groups (the model file; the pipeline's options are
//! the face's, `crate::face::PipelineOptions`) and the helpers behind them (the model file read from
//! its flag). Commands import from here, from `blob_rows` (a
//! blob read and evaluated on rows) and from `cli` itself, never from each other.

use crate::error::Result;

/// The nominal model: a model file, or the built-in planar RR arm.
#[derive(Debug, Clone, clap::Args)]
pub struct ModelArgs {
    /// Model file (TOML: DH table or URDF, units, CSV columns). Without it: the paper's RR arm,
    /// CSV columns q1, q2 (radians), x, y.
    #[arg(long)]
    pub model: Option<std::path::PathBuf>,
}

impl crate::face::ArmModel {
    /// Reads `args.model` (the command's one parse of its model file), or takes the built-in RR arm.
    /// Reading the file is the command's part: the face's own functions take the arm parsed.
    pub fn read(args: &ModelArgs) -> Result<Self> {
        match &args.model {
            Some(path) => Self::from_file(path, crate::data::model_file::load_model_file(path)?),
            None => Ok(Self::builtin_rr()),
        }
    }
}

//! `cbd diagnose`: structure left in the residual, traced to physical effects of the library,
//! selected out of sample, reported with the error before and after on held-out rows
//! (`crate::face::diagnose`).

use crate::cli::{ArmModel, ModelArgs};
use crate::error::{Error, Result};
use crate::face::{Dataset, DiagnoseSettings};
use std::path::PathBuf;

#[derive(Debug, clap::Args)]
pub struct DiagnoseArgs {
    #[command(flatten)]
    pub model: ModelArgs,
    /// Measurements to diagnose (CSV, the model file's columns).
    #[arg(long)]
    pub data: PathBuf,
    /// Held-out measurements for the before/after table (never used for fitting or selection).
    /// Without it, a fifth of --data is held out.
    #[arg(long)]
    pub test: Option<PathBuf>,
    /// Write the diagnosis as JSON here.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Write the residual-against-joint figure (PNG and SVG) into this directory.
    #[arg(long)]
    pub plots: Option<PathBuf>,
    /// Write the model file with the geometric corrections in its DH table and the effects
    /// found in [[effects]] (needs --model).
    #[arg(long)]
    pub write_model: Option<PathBuf>,
    #[command(flatten)]
    pub settings: DiagnoseSettings,
}

pub fn run(args: DiagnoseArgs) -> Result<()> {
    args.settings.validate()?;
    if args.write_model.is_some() && args.model.model.is_none() {
        return Err(Error::InvalidInput("--write-model needs --model (the file the corrections are written into)".into()));
    }
    crate::io::check_paths(
        &[("--model", args.model.model.as_deref()), ("--data", Some(&args.data)), ("--test", args.test.as_deref())],
        &[("--json", args.json.as_deref()), ("--write-model", args.write_model.as_deref())],
    )?;
    if let Some(dir) = &args.plots {
        crate::io::check_output_dir("--plots", dir)?;
    }
    let arm = ArmModel::read(&args.model)?;
    let data = Dataset::read(&args.data, &arm.spec)?;
    let test = args.test.as_ref().map(|path| Dataset::read(path, &arm.spec)).transpose()?;
    let d = crate::face::diagnose(&arm, &data, test.as_ref(), &args.settings)?;
    outln!("{}", d.text());
    if let Some(dir) = &args.plots {
        let files = d.write_figures(dir)?;
        outln!("figures written to {} ({files} files)", dir.display());
    }
    if let Some(path) = &args.write_model {
        if let Some(text) = d.model_file(&arm, path)? {
            crate::cli::write_atomically(path, text.as_bytes())?;
            outln!("model with the found effects written to {}", path.display());
        }
    }
    if let Some(path) = &args.json {
        let text = serde_json::to_string_pretty(&d.to_json()).map_err(Error::JsonOutput)?;
        crate::cli::write_atomically(path, text.as_bytes())?;
    }
    Ok(())
}

//! `cbd compare`: every peer on the same data in one run (`crate::face::compare`) — nominal,
//! parametric DH calibration, kernel ridge (GP) regression of the residual, Calibration by
//! Diffeomorphisms, and the hybrids.

use crate::cli::ArmModel;
use crate::face::{CompareSettings, Dataset};
use std::path::PathBuf;

#[derive(Debug, clap::Args)]
pub struct CompareArgs {
    /// Model file (DH table or URDF, units, CSV columns).
    #[arg(long)]
    pub model: PathBuf,
    /// Training measurements (CSV).
    #[arg(long)]
    pub train: PathBuf,
    /// Test measurements (CSV); never used for fitting or tuning.
    #[arg(long)]
    pub test: PathBuf,
    /// Write the results as JSON here (one object per method under "methods").
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Write a chart of every method's test-error distribution (PNG and SVG) into this directory.
    #[arg(long)]
    pub plots: Option<PathBuf>,
    #[command(flatten)]
    pub settings: CompareSettings,
}

pub fn run(args: CompareArgs) -> crate::Result<()> {
    crate::io::check_paths(
        &[("--model", Some(&args.model)), ("--train", Some(&args.train)), ("--test", Some(&args.test))],
        &[("--json", args.json.as_deref())],
    )?;
    if let Some(dir) = &args.plots {
        crate::io::check_output_dir("--plots", dir)?;
    }
    let arm = ArmModel::from_file(&args.model, crate::data::model_file::load_model_file(&args.model)?)?;
    args.settings.check(&arm)?;
    let train = Dataset::read(&args.train, &arm.spec)?;
    let test = Dataset::read(&args.test, &arm.spec)?;
    let c = crate::face::compare(&arm, &train, &test, &args.settings)?;
    outln!("{}", c.table());
    for note in c.notes() {
        outln!("{note}");
    }
    if let Some(dir) = &args.plots {
        let files = c.write_figures(dir)?;
        outln!("figures written to {} ({files} files)", dir.display());
    }
    if let Some(table) = c.commanded_table() {
        outln!("{table}");
    }
    if let Some(path) = &args.json {
        let text = serde_json::to_string_pretty(&c.to_json()).map_err(crate::Error::JsonOutput)?;
        crate::cli::write_atomically(path, text.as_bytes())?;
    }
    Ok(())
}

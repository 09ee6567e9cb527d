//! `cbd fit`: train a model blob from measured data.

use crate::cli::{ArmModel, ModelArgs};
use crate::error::{Error, Result};
use std::path::PathBuf;

#[derive(Debug, clap::Args)]
pub struct FitArgs {
    #[command(flatten)]
    pub model: ModelArgs,
    /// Training measurements (CSV).
    #[arg(long)]
    pub data: PathBuf,
    /// Output blob: a new path or a regular file (replaced atomically); `-` writes it to standard output.
    #[arg(long)]
    pub out: PathBuf,
    /// Write what the pipeline chose and measured as JSON here: hyperparameters (data units), evidence,
    /// scheme and its cross-validation, the fit's report, warnings.
    #[arg(long)]
    pub json: Option<PathBuf>,
    #[command(flatten)]
    pub settings: crate::face::FitSettings,
}

pub fn run(args: FitArgs) -> Result<()> {
    args.settings.validate()?;
    crate::io::check_paths(
        &[("--model", args.model.model.as_deref()), ("--data", Some(&args.data))],
        &[("--out", Some(&args.out)), ("--json", args.json.as_deref())],
    )?;
    let arm = ArmModel::read(&args.model)?;
    let imported = crate::data::csv_import::read_measurements(&args.data, &arm.spec)?;
    let data = crate::face::Dataset { source: args.data.clone(), imported };
    let fitted = crate::face::fit(&arm, &data, &args.settings)?;
    crate::cli::write_atomically(&args.out, &fitted.blob)?;
    if let Some(path) = &args.json {
        let text = serde_json::to_string_pretty(&fitted.report).map_err(Error::JsonOutput)?;
        crate::cli::write_atomically(path, text.as_bytes())?;
    }
    let summary = format!("{}; blob {} bytes written to {}", fitted.summary, fitted.blob.len(), args.out.display());
    // With `--out -` standard output carries the blob; the summary must not corrupt it.
    if crate::cli::is_stdout(&args.out) {
        errln!("{summary}");
        errln!("{}", fitted.noise_floor);
        if !args.settings.pipeline.quiet {
            errln!("{}", fitted.memory);
        }
    } else {
        outln!("{summary}");
        outln!("{}", fitted.noise_floor);
        if !args.settings.pipeline.quiet {
            outln!("{}", fitted.memory);
        }
    }
    Ok(())
}

//! `cbd compare`: every peer on the same data in one run — nominal, parametric DH calibration,
//! kernel ridge (GP) regression of the residual, Calibration by Diffeomorphisms, and the hybrids.

use crate::baselines::compare::{compare_files, Predictor};
use crate::data::Measurements;
use crate::kernels::hyperparameters::{choose_hyperparameters, SearchOptions};
use cbd_protocol::NominalModel;
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
    /// Integration steps of the CbD flow (Euler). One step is the linearised model, whose
    /// Jacobian is exact in closed form (fast for N ≈ 1000); more steps need the tangent flow.
    #[arg(long, default_value_t = 1)]
    pub steps: u16,
}

/// CbD fitted on `nominal` with hyperparameters chosen by the GP marginal likelihood on `data`.
pub fn cbd_fitter(search: &SearchOptions, steps: u16) -> impl Fn(&NominalModel, &Measurements) -> Result<Predictor, String> + '_ {
    move |nominal: &NominalModel, data: &Measurements| -> Result<Predictor, String> {
        let h = choose_hyperparameters(nominal, data, search).map_err(|e| e.to_string())?;
        let mut opts = crate::kernels::cbd_options_from_gp(&h, data);
        opts.integrator.steps = steps;
        let fit = crate::solver::fit_cbd(nominal, data, &opts).map_err(|e| e.to_string())?;
        let blob = fit.blob;
        Ok(Box::new(move |joints: &[f64]| crate::predict::evaluate_blob(&blob, joints).unwrap_or_else(|_| vec![f64::NAN; joints.len()])))
    }
}

pub fn run(args: CompareArgs) -> Result<(), String> {
    if args.steps == 0 || args.steps > cbd_protocol::MAX_STEPS {
        return Err(format!("--steps must be between 1 and {}, got {}", cbd_protocol::MAX_STEPS, args.steps));
    }
    let search = SearchOptions::default();
    let fitter = cbd_fitter(&search, args.steps);
    let (comparison, warnings) = compare_files(&args.model, &args.train, &args.test, &search, Some(&fitter)).map_err(|e| e.to_string())?;
    for w in warnings {
        eprintln!("warning: {w}");
    }
    let unit = crate::data::model_file::load_model_file(&args.model).map(|m| m.length_unit.name()).unwrap_or("length units");
    println!("{}", comparison.table(unit));
    for r in &comparison.rows {
        if !r.note.is_empty() {
            println!("{}: {}", r.name, r.note);
        }
    }
    if let Some(dir) = &args.plots {
        let methods: Vec<(String, Vec<f64>)> =
            comparison.rows.iter().filter(|r| !r.test_errors.is_empty()).map(|r| (r.name.clone(), r.test_errors.clone())).collect();
        let files = crate::report::plots::method_comparison(dir, &methods, unit)?;
        println!("figures written to {} ({} files)", dir.display(), files.len());
    }
    if let Some(path) = &args.json {
        let text = serde_json::to_string_pretty(&comparison.to_json()).map_err(|e| e.to_string())?;
        crate::cli::write_atomically(path, text.as_bytes())?;
    }
    Ok(())
}

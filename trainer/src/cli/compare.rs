//! `cbd compare`: every peer on the same data in one run — nominal, parametric DH calibration,
//! kernel ridge (GP) regression of the residual, Calibration by Diffeomorphisms, and the hybrids.

use crate::baselines::compare::{compare_peers, read_compare_files, FittedCorrection, Predictor};
use crate::data::Measurements;
use crate::kernels::hyperparameters::SearchOptions;
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
    /// The data come from `cbd simulate --robot <rr|six>`: add the commanded-accuracy table (true
    /// tool error of that simulated arm after each method's compensation, 1000 random reachable
    /// targets; JSON key `commanded`). Fits DH, kernel ridge and CbD again for it.
    #[arg(long)]
    pub commanded: Option<String>,
    /// CbD's hyperparameters and scheme, as in `cbd fit` (chosen by the pipeline when unset).
    #[command(flatten)]
    pub solver: crate::cli::fit::SolverArgs,
}

/// CbD through the one calibration pipeline (`crate::calibrate`) on whatever base model the caller
/// gives (nominal, DH-calibrated, with effects): the blob `cbd fit` writes for the same data and flags.
pub fn cbd_fitter(settings: &crate::calibrate::Settings) -> impl Fn(&NominalModel, &Measurements) -> crate::Result<FittedCorrection> + '_ {
    move |nominal: &NominalModel, data: &Measurements| -> crate::Result<FittedCorrection> {
        let calibration = crate::calibrate::calibrate(nominal, data, settings)?;
        crate::cli::fit::print_calibration(&calibration, !settings.verbose);
        let mut note = calibration.describe_hyperparameters();
        if let Some(e) = &calibration.evidence {
            note += &format!("; evidence {:.2} on {} rows ({:.2} s)", e.log_evidence, e.rows_used, e.seconds);
        }
        note += &format!("; {} ({})", calibration.scheme.label(), calibration.scheme.chosen_by);
        for w in &calibration.warnings {
            note += &format!("; warning: {w}");
        }
        let blob = calibration.fit.blob;
        let predictor: Predictor =
            Box::new(move |joints: &[f64]| crate::predict::evaluate_blob(&blob, joints).unwrap_or_else(|_| vec![f64::NAN; joints.len()]));
        Ok((predictor, note))
    }
}

pub fn run(args: CompareArgs) -> crate::Result<()> {
    crate::io::check_paths(
        &[("--model", Some(&args.model)), ("--train", Some(&args.train)), ("--test", Some(&args.test))],
        &[("--json", args.json.as_deref())],
    )?;
    if let Some(dir) = &args.plots {
        crate::io::check_output_dir("--plots", dir)?;
    }
    let mut settings = args.solver.settings()?;
    // The table is the output here; the fits' own progress lines would drown it.
    settings.verbose = false;
    let search = SearchOptions::default();
    let inputs = read_compare_files(&args.model, &args.train, &args.test)?;
    if let Some(r) = &inputs.registration {
        let unit = crate::data::model_file::load_model_file(&args.model).map(|m| m.length_unit.name()).unwrap_or("length units");
        eprintln!("{}: {}", args.train.display(), r.describe(unit));
    }
    let mut warnings = inputs.warnings;
    for (path, imported) in [(&args.train, &inputs.train), (&args.test, &inputs.test)] {
        warnings.extend(crate::data::nominal_check::nominal_warnings(&inputs.nominal, &imported.measurements, &imported.lines, path)?);
    }
    for w in warnings {
        eprintln!("warning: {w}");
    }
    if let Some(robot) = &args.commanded {
        crate::baselines::commanded::commanded_arm(robot, &inputs.nominal)?;
    }
    // CbD and the hybrids fit all training rows: refuse up front what cannot fit in memory.
    let train = &inputs.train.measurements;
    let threads = crate::cli::memory::check_fit_of(
        &args.train,
        train,
        "use fewer training rows (cbd fit --max-rows N fits an evenly spaced subset)",
    )?;
    settings.threads = Some(threads);
    let fitter = cbd_fitter(&settings);
    let comparison =
        crate::workers::on_workers(threads, || compare_peers(&inputs.nominal, train, &inputs.test.measurements, &search, Some(&fitter)));
    let unit = crate::data::model_file::load_model_file(&args.model).map(|m| m.length_unit.name()).unwrap_or("length units");
    println!("{}", comparison.table(unit));
    for w in comparison.warnings() {
        eprintln!("warning: {w}");
    }
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
    let commanded = match &args.commanded {
        Some(robot) => Some(crate::workers::on_workers(threads, || {
            crate::baselines::commanded::run_for_compare(robot, &inputs.nominal, train, &search, &settings, unit)
        })?),
        None => None,
    };
    if let Some(path) = &args.json {
        let mut json = comparison.to_json();
        if let Some(r) = &inputs.registration {
            json["registered_base"] = r.to_json();
        }
        if let Some(c) = &commanded {
            json["commanded"] = c.to_json();
        }
        let text = serde_json::to_string_pretty(&json).map_err(crate::Error::JsonOutput)?;
        crate::cli::write_atomically(path, text.as_bytes())?;
    }
    Ok(())
}

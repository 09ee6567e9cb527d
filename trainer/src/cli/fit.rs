//! `cbd fit`: train a model blob from measured data.

use crate::cli::args::{print_calibration, SolverArgs};
use crate::cli::{ArmModel, ModelArgs};
use crate::error::{Context, Error, Result};
use std::path::PathBuf;

#[derive(Debug, clap::Args, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FitArgs {
    #[command(flatten)]
    #[serde(flatten)]
    pub model: ModelArgs,
    /// Training measurements (CSV).
    #[arg(long)]
    pub data: PathBuf,
    /// Output blob: a new path or a regular file (replaced atomically); `-` writes it to standard output.
    #[arg(long)]
    pub out: PathBuf,
    /// Whether the chain's geometric group (DH parameters, base, tool) is calibrated before the
    /// flows (Levenberg–Marquardt; the blob then carries the calibrated chain): auto chooses by CbD's
    /// own evidence on the training rows (cross-validation where no evidence runs), nominal deforms
    /// the chain as given, calibrated always calibrates it first.
    #[arg(long, value_enum, default_value_t = crate::cli::args::defaults::geometry())]
    #[serde(default = "crate::cli::args::defaults::geometry")]
    pub geometry: crate::calibrate::Geometry,
    /// The same as `--geometry calibrated`.
    #[arg(long, conflicts_with = "geometry")]
    #[serde(default)]
    pub dh_first: bool,
    /// Fit at most this many measurements, evenly spaced through the file (a fit needs memory
    /// growing as the square of the rows; the error for too many names a value that fits).
    #[arg(long)]
    pub max_rows: Option<usize>,
    /// Write what the pipeline chose and measured as JSON here: hyperparameters (data units), evidence,
    /// scheme and its cross-validation, the fit's report, warnings.
    #[arg(long)]
    pub json: Option<PathBuf>,
    #[command(flatten)]
    #[serde(flatten)]
    pub solver: SolverArgs,
}

/// The noise floor of the chosen σ and where the cross-validated held-out error stands against it.
fn describe_noise_floor(c: &crate::calibrate::Calibration, unit: &str) -> String {
    let (floor, held_out) = c.noise_floor();
    let verdict = match held_out {
        Some(v) => format!("; held-out RMS (scheme cross-validation) {}", v.describe()),
        None => "; no held-out error measured (no cross-validation ran)".into(),
    };
    format!("{}{verdict}", floor.describe(unit))
}

/// At most `max_rows` of `data`'s rows, evenly spaced (all of them without a limit).
fn evenly_spaced_rows(data: crate::data::Measurements, max_rows: Option<usize>) -> crate::data::Measurements {
    match max_rows {
        Some(k) if k < data.len() => data.subset(&data.evenly_spaced_pose_rows(k)),
        _ => data,
    }
}

/// The flags' values, before any work.
fn check_flags(args: &FitArgs) -> Result<()> {
    args.solver.validate()?;
    // The command line refuses both flags given (clap's `conflicts_with`); keyword arguments here.
    if args.dh_first && args.geometry != crate::calibrate::Geometry::Auto {
        return Err(Error::InvalidInput("--dh-first cannot be used with --geometry (it is --geometry calibrated)".into()));
    }
    if args.max_rows.is_some_and(|k| k < 2) {
        return Err(Error::InvalidInput("--max-rows must be at least 2".into()));
    }
    Ok(())
}

pub fn run(args: FitArgs) -> Result<()> {
    check_flags(&args)?;
    crate::io::check_paths(
        &[("--model", args.model.model.as_deref()), ("--data", Some(&args.data))],
        &[("--out", Some(&args.out)), ("--json", args.json.as_deref())],
    )?;
    let arm = ArmModel::read(&args.model)?;
    let imported = crate::data::csv_import::read_measurements(&args.data, &arm.spec)?;
    let fitted = fit_measurements(&args, &arm, imported)?;
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
        if !args.solver.quiet {
            errln!("{}", fitted.memory);
        }
    } else {
        outln!("{summary}");
        outln!("{}", fitted.noise_floor);
        if !args.solver.quiet {
            outln!("{}", fitted.memory);
        }
    }
    Ok(())
}

/// What the memory checks estimated before allocating and what this process held at its peak
/// (address space: what `ulimit -v` must allow; resident: what a cgroup limit must allow), bytes.
fn memory_report() -> serde_json::Value {
    use crate::cli::memory;
    serde_json::json!({
        "estimated_bytes": memory::needed_so_far(),
        "peak_address_space_bytes": memory::peak_mapped_bytes(),
        "peak_resident_bytes": memory::peak_resident_bytes(),
    })
}

/// "memory: about 412 MB estimated before allocating; peak address space 398 MB, resident 376 MB".
fn describe_memory(m: &serde_json::Value) -> String {
    let gb = |key: &str| m[key].as_f64().map_or("unknown".to_string(), crate::cli::memory::gigabytes);
    format!(
        "memory: about {} estimated before allocating; peak address space {}, resident {}",
        gb("estimated_bytes"),
        gb("peak_address_space_bytes"),
        gb("peak_resident_bytes")
    )
}

/// What [`fit_measurements`] produced: the blob, the `--json` report, the summary line and the
/// noise floor's.
pub struct Fitted {
    pub blob: Vec<u8>,
    pub report: serde_json::Value,
    pub summary: String,
    pub noise_floor: String,
    /// What the memory checks estimated and the process's peak ([`describe_memory`]).
    pub memory: String,
}

/// The fit `cbd fit` runs, on measurements already read with `arm`'s column spec (`args.data`
/// names them in messages; `args.model` is not read again — `arm` is it; `args.out` and
/// `args.json` are not written here). One function for the command and the Python package, so
/// both give the same blob for the same data and flags.
pub fn fit_measurements(args: &FitArgs, arm: &ArmModel, imported: crate::data::csv_import::ImportedMeasurements) -> Result<Fitted> {
    let mut nominal = arm.nominal.clone();
    check_flags(args)?;
    for w in imported.warnings(&args.data) {
        errln!("warning: {w}");
    }
    let registration = crate::cli::register_base_if_unknown(arm, &mut nominal, &imported.measurements, &args.data)?;
    for w in
        crate::data::nominal_check::nominal_warnings(&nominal, &imported.measurements, &imported.lines, &args.data, registration.is_some())?
    {
        errln!("warning: {w}");
    }
    let data = evenly_spaced_rows(imported.measurements, args.max_rows);
    args.solver.check_against(&data, &args.data)?;
    let mut settings = args.solver.settings()?;
    // The kernel form's (N m)² matrices are checked up front; the expansion needs none, so with it
    // the solver checks only if it falls back to the kernel form (against what the workers leave).
    // The workers' own memory (faer's multiply workspace, stacks) is checked either way.
    let threads = if settings.solver.representation == crate::expansion::Representation::Kernel {
        crate::cli::memory::check_fit_of(&args.data, &data, "--max-rows N fits an evenly spaced subset of N rows")?
    } else {
        crate::cli::memory::check_workers_of(&args.data, data.len() * data.task_dim, "--max-rows N fits an evenly spaced subset of N rows")?
    };
    settings.solver.memory_budget = crate::cli::memory::kernel_form_budget(threads, data.len() * data.task_dim);
    settings.geometry = if args.dh_first { crate::calibrate::Geometry::Calibrated } else { args.geometry };
    settings.solver.threads = threads;
    let calibration =
        crate::workers::on_workers(threads, || crate::calibrate::calibrate(&nominal, &data, &settings)).context(args.data.display())?;
    print_calibration(&calibration, args.solver.quiet);
    let mut report = calibration.to_json();
    if let Some(r) = &registration {
        report["registered_base"] = r.to_json();
    }
    let r = &calibration.fit.report;
    let last = r.log.last().map(|l| l.train_rms).unwrap_or(f64::NAN);
    let summary = format!(
        "fitted {} measurements in {:.2} s: {} iterations ({}), training RMS error {:.3e}",
        data.len(),
        r.seconds,
        r.iterations,
        r.stop_reason,
        last
    );
    // The model's length unit (the data are read into it): the floor's line names it.
    let unit = arm.length_unit();
    let mut noise_floor = describe_noise_floor(&calibration, unit);
    // Drift in measurement order (issue 49 item 2), on the residual of the DH-calibrated chain (the
    // one CbD deforms, or fitted for the test where the nominal was kept: a nominal chain's error
    // of millimetres leaves second-order shape the test's joint kernel must carry, and the UR5
    // rows' drift went unseen there): beside the floor, and recorded in the blob when found.
    let chain = match &calibration.dh {
        Some(_) => calibration.base.clone(),
        None => crate::parametric::calibrate_dh(&nominal, &data, &Default::default()).map_or(calibration.base.clone(), |f| f.model),
    };
    let drift = crate::diagnose::drift::drift_of_chain(&chain, &data, &Default::default());
    let found = drift.as_ref().filter(|d| d.detected);
    let blob = with_record(&calibration.fit.blob, found, crate::data::import_frame::import_frame(&arm.spec))?;
    if let Some(d) = &drift {
        report["drift"] = serde_json::to_value(d).map_err(Error::JsonOutput)?;
        if d.detected {
            noise_floor += &format!(
                "\ndrift in measurement order: sd {:.3e} {unit} per coordinate over {:.1} poses ({:.0} % of the variance a model of \
                 the configuration calls noise; {:.0} nats), recorded in the blob — {}",
                d.sd,
                d.length,
                100.0 * d.share_of_floor,
                d.log_likelihood_ratio,
                d.advice()
            );
        }
    }
    report["memory"] = memory_report();
    let memory = describe_memory(&report["memory"]);
    Ok(Fitted { blob, report, summary, noise_floor, memory })
}

/// `blob` with what the calibration found about its rows recorded, every other byte of its model
/// unchanged: the drift `d` beside σ (format 8), and the import `frame` the rows were read through
/// (format 9, `cbd_protocol::Provenance`). Nothing to record: `blob` as it is.
fn with_record(blob: &[u8], d: Option<&crate::diagnose::drift::Drift>, frame: Option<cbd_protocol::ImportFrame>) -> Result<Vec<u8>> {
    if d.is_none() && frame.is_none() {
        return Ok(blob.to_vec());
    }
    let internal = |e: String| Error::Internal(format!("recording the drift and the import frame in the blob: {e}"));
    let mut model = cbd_protocol::decode(blob).map_err(|e| internal(e.to_string()))?;
    model.drift = d.map(|d| cbd_protocol::RowDrift { sd: d.sd, length: d.length });
    model.provenance = frame.map(|f| cbd_protocol::Provenance { import_frame: Some(f), parent: None });
    cbd_protocol::encode_to_vec(&model).map_err(|e| internal(e.to_string()))
}

//! A calibration fitted: measurements and the pipeline's options in, the blob's bytes and the report out.

use super::settings::{defaults, PipelineOptions};
use super::{ArmModel, Dataset};
use crate::error::{Context, Error, Result};

/// What a fit is asked to do beyond the data: the geometry choice, a cap on the rows, the pipeline's
/// options. The flags of `cbd fit` and the keywords of the Python package's `fit` (one set of defaults).
#[derive(Debug, Clone, clap::Args, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FitSettings {
    /// Whether the chain's geometric group (DH parameters, base, tool) is calibrated before the
    /// flows (Levenberg–Marquardt; the blob then carries the calibrated chain): auto chooses by CbD's
    /// own evidence on the training rows (cross-validation where no evidence runs), nominal deforms
    /// the chain as given, calibrated always calibrates it first.
    #[arg(long, value_enum, default_value_t = defaults::geometry())]
    #[serde(default = "defaults::geometry")]
    pub geometry: crate::calibrate::Geometry,
    /// The same as `--geometry calibrated`.
    #[arg(long, conflicts_with = "geometry")]
    #[serde(default)]
    pub dh_first: bool,
    /// Fit at most this many measurements, evenly spaced through the file (a fit needs memory
    /// growing as the square of the rows; the error for too many names a value that fits).
    #[arg(long)]
    pub max_rows: Option<usize>,
    #[command(flatten)]
    #[serde(flatten)]
    pub pipeline: PipelineOptions,
}

impl FitSettings {
    /// Rejects out-of-range values before any work, naming the flag.
    pub fn validate(&self) -> Result<()> {
        self.pipeline.validate()?;
        // The command line refuses both flags given (clap's `conflicts_with`); keyword arguments here.
        if self.dh_first && self.geometry != crate::calibrate::Geometry::Auto {
            return Err(Error::InvalidInput("--dh-first cannot be used with --geometry (it is --geometry calibrated)".into()));
        }
        if self.max_rows.is_some_and(|k| k < 2) {
            return Err(Error::InvalidInput("--max-rows must be at least 2".into()));
        }
        Ok(())
    }
}

/// A fitted calibration: the blob the runtime loads and what the fit chose and measured.
pub struct Calibration {
    /// The model blob's bytes.
    pub blob: Vec<u8>,
    /// What the pipeline chose and measured (`cbd fit --json`): hyperparameters in data units,
    /// evidence, scheme and its cross-validation, the fit's report, warnings, drift, memory.
    pub report: serde_json::Value,
    /// "fitted N measurements in … s: … iterations (…), training RMS error …".
    pub summary: String,
    /// The noise floor of the chosen σ, the held-out error against it, and the drift when found.
    pub noise_floor: String,
    /// What the memory checks estimated and the process's peak ([`describe_memory`]).
    pub memory: String,
}

/// Fits `arm`'s calibration to `data`: the one fit `cbd fit` and the Python package run, so both
/// give the same blob for the same data and settings. Warnings and what the pipeline chose go to
/// the crate's message channel as the fit runs.
pub fn fit(arm: &ArmModel, data: &Dataset, settings: &FitSettings) -> Result<Calibration> {
    settings.validate()?;
    let imported = &data.imported;
    let source = data.source.as_path();
    let mut nominal = arm.nominal.clone();
    for w in imported.warnings(source) {
        errln!("warning: {w}");
    }
    let registration = super::register_base_if_unknown(arm, &mut nominal, &imported.measurements, source)?;
    let data =
        crate::data::preparation::fit_rows(&nominal, imported, source, registration.is_some(), settings.max_rows, settings.pipeline.sigma)?;
    let mut pipeline = settings.pipeline.settings()?;
    pipeline.geometry = if settings.dh_first { crate::calibrate::Geometry::Calibrated } else { settings.geometry };
    pipeline.drift = Some(Default::default());
    // Every subset a stage takes (the evidence's rows, the folds, the drift test's window), cut once here.
    let data = crate::data::stage_rows::StageRows::new(data, &pipeline.cuts());
    let unknowns = data.len() * data.rows.task_dim;
    // The kernel form's (N m)² matrices are checked up front; the expansion needs none, so with it
    // the solver checks only if it falls back to the kernel form (against what the workers leave).
    // The workers' own memory (faer's multiply workspace, stacks) is checked either way.
    let threads = if pipeline.solver.representation == crate::expansion::Representation::Kernel {
        crate::memory::check_fit_of(source, data.len(), data.rows.task_dim, "--max-rows N fits an evenly spaced subset of N rows")?
    } else {
        crate::memory::check_workers_of(source, unknowns, "--max-rows N fits an evenly spaced subset of N rows")?
    };
    pipeline.solver.memory_budget = crate::memory::kernel_form_budget(threads, unknowns);
    pipeline.solver.threads = threads;
    let calibration =
        crate::memory::on_workers(threads, || crate::calibrate::calibrate_rows(&nominal, &data, &pipeline)).context(source.display())?;
    print_calibration(&calibration, settings.pipeline.quiet);
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
    // Drift in measurement order (`calibrate::drift_test`): beside the floor, and recorded in the blob when found.
    let drift = &calibration.drift;
    let found = drift.as_ref().filter(|d| d.detected);
    let blob = with_record(&calibration.fit.blob, found, crate::data::import_frame::import_frame(&arm.spec))?;
    if let Some(d) = drift {
        report["drift"] = serde_json::to_value(d).map_err(Error::JsonOutput)?;
        if d.detected {
            noise_floor += &format!(
                "\ndrift in measurement order: sd {:.3e} {unit} per coordinate over {} ({:.0} % of the variance a model of \
                 the configuration calls noise; {:.0} nats), recorded in the blob — {}",
                d.sd,
                d.length_text(),
                100.0 * d.share_of_floor,
                d.log_likelihood_ratio,
                d.advice()
            );
        }
    }
    report["memory"] = memory_report();
    let memory = describe_memory(&report["memory"]);
    Ok(Calibration { blob, report, summary, noise_floor, memory })
}

/// `blob` with what the calibration found about its rows recorded, every other byte of its model
/// unchanged: the drift `d` beside σ (format 8), and the import `frame` the rows were read through
/// (format 9, `cbd_protocol::Provenance`). Nothing to record: `blob` as it is.
fn with_record(blob: &[u8], d: Option<&crate::calibrate::drift_test::Drift>, frame: Option<cbd_protocol::ImportFrame>) -> Result<Vec<u8>> {
    if d.is_none() && frame.is_none() {
        return Ok(blob.to_vec());
    }
    let internal = |e: String| Error::Internal(format!("recording the drift and the import frame in the blob: {e}"));
    let mut model = cbd_protocol::decode(blob).map_err(|e| internal(e.to_string()))?;
    model.drift = d.map(|d| cbd_protocol::RowDrift { sd: d.sd, length: d.length });
    model.provenance = frame.map(|f| cbd_protocol::Provenance { import_frame: Some(f), parent: None });
    cbd_protocol::encode_to_vec(&model).map_err(|e| internal(e.to_string()))
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

/// What the memory checks estimated before allocating and what this process held at its peak
/// (address space: what `ulimit -v` must allow; resident: what a cgroup limit must allow), bytes.
fn memory_report() -> serde_json::Value {
    use crate::memory;
    serde_json::json!({
        "estimated_bytes": memory::needed_so_far(),
        "peak_address_space_bytes": memory::peak_mapped_bytes(),
        "peak_resident_bytes": memory::peak_resident_bytes(),
    })
}

/// "memory: about 412 MB estimated before allocating; peak address space 398 MB, resident 376 MB".
fn describe_memory(m: &serde_json::Value) -> String {
    let gb = |key: &str| m[key].as_f64().map_or("unknown".to_string(), crate::memory::gigabytes);
    format!(
        "memory: about {} estimated before allocating; peak address space {}, resident {}",
        gb("estimated_bytes"),
        gb("peak_address_space_bytes"),
        gb("peak_resident_bytes")
    )
}

/// Prints what the pipeline chose (stderr) and its warnings.
pub fn print_calibration(c: &crate::calibrate::Calibration, quiet: bool) {
    if let Some(dh) = &c.dh {
        errln!("DH calibration: {} iterations, rank {}/{}, training RMS {:.4e}", dh.iterations, dh.rank, dh.n_parameters, dh.final_rms);
    }
    if !quiet {
        errln!("{}", c.geometry.describe());
        if let Some(f) = &c.configuration {
            errln!("{}", f.describe());
        }
        match &c.evidence {
            Some(e) => errln!(
                "hyperparameters (CbD evidence {:.2} on {} rows, {} evaluations, {:.2} s): {}",
                e.log_evidence,
                e.rows_used,
                e.evaluations,
                e.seconds,
                c.describe_hyperparameters()
            ),
            None => errln!("hyperparameters: {}", c.describe_hyperparameters()),
        }
        let cv: Vec<String> =
            c.scheme.cross_validation.iter().map(|(i, e)| format!("{} {e:.3e}", crate::calibrate::scheme::label(*i))).collect();
        errln!(
            "scheme: {} ({}{})",
            c.scheme.label(),
            c.scheme.chosen_by,
            if cv.is_empty() { String::new() } else { format!(": held-out RMS {}", cv.join(", ")) }
        );
    }
    for w in &c.warnings {
        errln!("warning: {w}");
    }
}

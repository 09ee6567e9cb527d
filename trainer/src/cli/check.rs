//! `cbd check`: does the calibration on the controller still hold? Fresh poses against the blob's
//! own posterior predictive distribution (`evaluation::check`, docs/DESIGN.md "cbd check"); exit 0
//! when it holds, 3 when it changed (docs/EXIT_CODES.md).

use crate::cli::blob_rows::{decode_fitting, evaluate_rows, finite_statistics, recorded_sigma};
use crate::cli::{ArmModel, ModelArgs};
use crate::error::{Context, Error, Result};
use crate::evaluation::check::{check, CheckError, Verdict};
use crate::report::checks::p_text;
use crate::report::noise_floor::NoiseFloor;
use std::path::{Path, PathBuf};

#[derive(Debug, clap::Args)]
pub struct CheckArgs {
    #[command(flatten)]
    pub model: ModelArgs,
    /// The calibrated model on the controller.
    #[arg(long)]
    pub blob: PathBuf,
    /// Fresh measurements (CSV, in measurement order; typically 10–30 poses).
    #[arg(long)]
    pub data: PathBuf,
    /// The test's level: "changed" when p < alpha (0 < alpha < 1).
    #[arg(long, default_value_t = 0.01)]
    pub alpha: f64,
    /// Fit the fresh rows' rigid frame first (a tracker set up anew); also when the model file's
    /// base is `register = true`.
    #[arg(long)]
    pub register: bool,
    /// Write the verdict and the statistics as JSON here.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Append one JSON line per check here (time, p, error, verdict, the noise floor, the named
    /// change); `cbd report --checks` draws the trend.
    #[arg(long)]
    pub log: Option<PathBuf>,
    /// When the calibration changed and the change is named: refit only the named change on the
    /// fresh poses (the fields kept) and write the new blob to --out (it records its parent's hash);
    /// its error is reported on fresh poses held out of the update.
    #[arg(long, requires = "out")]
    pub update: bool,
    /// Where --update writes the new blob.
    #[arg(long, requires = "update")]
    pub out: Option<PathBuf>,
}

pub fn run(args: CheckArgs) -> Result<()> {
    if !(args.alpha > 0.0 && args.alpha < 1.0) {
        return Err(Error::InvalidInput(format!(
            "--alpha must be a number between 0 and 1 (exclusive), got {}",
            crate::error::number(args.alpha)
        )));
    }
    crate::io::check_paths(
        &[("--model", args.model.model.as_deref()), ("--blob", Some(&args.blob)), ("--data", Some(&args.data))],
        &[("--json", args.json.as_deref()), ("--log", args.log.as_deref()), ("--out", args.out.as_deref())],
    )?;
    let arm = ArmModel::read(&args.model)?;
    let register = args.register || arm.register_base();
    let (nominal, spec) = (arm.nominal, arm.spec);
    let imported = crate::data::csv_import::read_measurements(&args.data, &spec)?;
    let (data, lines) = (imported.measurements, imported.lines);
    let blob = crate::face::read_blob(&args.blob)?;
    let model = decode_fitting(&blob, &args.blob, &args.model, &nominal, &spec)?;
    if model.n_joints() != data.n_joints || model.task_dim() != data.task_dim {
        return Err(Error::InvalidInput(format!(
            "{}: {} joints and {}-D positions, but {} has {} joints and {}-D positions",
            args.data.display(),
            data.n_joints,
            data.task_dim,
            args.blob.display(),
            model.n_joints(),
            model.task_dim()
        )));
    }
    let Some(sigma) = recorded_sigma(&model, &args.blob)? else {
        return Err(Error::InvalidInput(format!("{}: {}", args.blob.display(), CheckError::NoSigma)));
    };
    let m = model.task_dim();
    let need = crate::evaluation::check::covariance::covariance_bytes(model.n_points as usize, data.len(), m);
    if let Some(available) = crate::cli::memory::available_bytes().filter(|a| need > *a) {
        return Err(Error::InvalidInput(format!(
            "{}: its {} measurement points and the {} fresh rows need about {} for the check's covariance, more than the {} this process may use; raise the memory limit",
            args.blob.display(),
            model.n_points,
            data.len(),
            crate::cli::memory::gigabytes(need),
            crate::cli::memory::gigabytes(available)
        )));
    }
    let mut storage = vec![0.0; cbd_runtime::storage_len_for(&model)];
    let mut cal = cbd_runtime::Calibrator::from_model(model.clone(), &mut storage).context(args.blob.display())?;
    crate::predict::check_calibrator(&mut cal).context(args.blob.display())?;
    let (predicted, far) = evaluate_rows(&mut cal, &data, &lines, &args.blob, &args.data, 0.05)?;
    // A blob whose chain is not the model file's carries a DH-calibrated geometry (`cbd fit`'s
    // default when the evidence chooses it): its parameters' uncertainty goes into C.
    let geometry = model.nominal != nominal;
    let options = crate::evaluation::check::CheckOptions { alpha: args.alpha, register, geometry };
    let result = check(&model, &data, &predicted, options).map_err(|e| {
        let file = if e == CheckError::NotPositiveDefinite || e == CheckError::NoSigma { &args.blob } else { &args.data };
        Error::InvalidInput(format!("{}: {e}", file.display()))
    })?;
    let after = finite_statistics("calibrated", &predicted, &result.measured, m, &lines, &args.data)?;
    let unit = spec.model_length_unit.name();
    // What a perfect model's error is on rows measured at another time: σ, and the recorded drift.
    let drift_sd = model.drift.map_or(0.0, |d| d.sd);
    let floor = NoiseFloor::new(
        (sigma * sigma + drift_sd * drift_sd).sqrt(),
        m,
        if model.drift.is_some() {
            "σ and the calibration's drift, recorded in the blob"
        } else {
            "the calibration's σ, recorded in the blob"
        },
    );
    let floor_verdict = floor.verdict(after.mean, data.len());
    if let Some(frame) = &result.frame {
        outln!(
            "{}: frame registered ({} dof, projected out of the test): {}",
            args.data.display(),
            crate::evaluation::check::register::FRAME_DOF,
            frame.describe(unit)
        );
    }
    outln!("{:<12} {:>11} {:>11} {:>11} {:>11}   / floor", "model", "mean", "median", "p99", "max");
    outln!(
        "{:<12} {:>11.4e} {:>11.4e} {:>11.4e} {:>11.4e} {:>9}",
        "calibrated",
        after.mean,
        after.median,
        after.p99,
        after.max,
        floor_verdict.cell()
    );
    outln!("{}; calibrated: {}", floor.describe(unit), floor_verdict.describe());
    let s = &result.statistic;
    let p = p_text(s.p_value);
    outln!(
        "statistic {:.4} on {} degrees of freedom (χ², the blob's predictive covariance at {} rows{}): p = {p}",
        s.statistic,
        s.dof,
        data.len(),
        if model.drift.is_some() { " with its recorded drift" } else { "" }
    );
    let verdict = match result.verdict {
        Verdict::Holds => "holds",
        Verdict::Changed => "changed",
    };
    outln!("{verdict} (p = {p}) at alpha = {}", args.alpha);
    // Naming the change (issue 50 item 3): only when it changed.
    let named = if result.verdict == Verdict::Changed {
        match crate::evaluation::check::name::name_change(
            &model,
            &data,
            &result.residual,
            &result.covariance,
            result.tangent.as_ref(),
            unit,
        ) {
            Ok(named) => Some(named),
            Err(e) => {
                errln!("warning: the change is not named: {}", name_error(e));
                None
            }
        }
    } else {
        None
    };
    if let Some(named) = &named {
        for (what, why) in &named.excluded {
            outln!("not offered: {what} ({why})");
        }
        if named.changes.is_empty() {
            outln!("no change of the library (joint zeros, link lengths and twists, encoder scales, base and tool shifts, length scale) explains the residual out of sample");
        } else {
            outln!("named change (leave-one-pose-out log predictive density {:.1} → {:.1}):", named.evidence_before, named.evidence_after);
            for change in &named.changes {
                outln!("  {}", change.describe());
            }
            let a = &named.after;
            outln!(
                "left after the named change: statistic {:.4} on {} degrees of freedom: p = {} ({})",
                a.statistic,
                a.dof,
                p_text(a.p_value),
                if a.p_value < args.alpha { "more changed than this" } else { "explained" }
            );
        }
    }
    let updated = match (&args.out, &named) {
        (Some(out), _) if result.verdict == Verdict::Holds => {
            outln!("--update: the calibration holds; {} is not written", out.display());
            None
        }
        (Some(out), Some(named)) => {
            let groups: Vec<_> = named.changes.iter().map(|c| c.candidate).collect();
            let updated = crate::evaluation::check::update::update(
                &model,
                &blob,
                crate::data::import_frame::import_frame(&spec),
                &data,
                &result.measured,
                &result.covariance,
                result.tangent.as_ref(),
                &groups,
            )
            .map_err(|e| Error::InvalidInput(format!("--update: {e}")))?;
            print_update(&updated, unit);
            crate::cli::write_atomically(out, &updated.blob)?;
            outln!("wrote {} ({} bytes; parent {})", out.display(), updated.blob.len(), &updated.parent[..16]);
            Some(updated)
        }
        (Some(_), None) => return Err(Error::InvalidInput("--update: the change is not named, so there is nothing to update".into())),
        (None, _) => None,
    };
    if far > 0 {
        errln!(
            "warning: {far} of {} configurations are far from every measured configuration (kernel support < 0.05): extrapolation",
            data.len()
        );
    }
    if let Some(path) = &args.json {
        let mut v = serde_json::json!({
            "verdict": result.verdict,
            "p_value": s.p_value,
            "statistic": s.statistic,
            "dof": s.dof,
            "alpha": args.alpha,
            "rows": data.len(),
            // The named change (empty when the calibration holds or nothing explains it).
            "changes": named.as_ref().map_or_else(Vec::new, |n| n.changes.iter().map(|c| c.to_json()).collect::<Vec<_>>()),
            "calibrated": after,
            "noise_floor": {"floor": floor, "calibrated": floor_verdict},
            "extrapolating": far,
        });
        if let Some(frame) = &result.frame {
            v["frame"] = frame.to_json();
        }
        if let Some(named) = &named {
            v["after_change"] = serde_json::json!({
                "statistic": named.after.statistic,
                "dof": named.after.dof,
                "p_value": named.after.p_value,
                "loo_log_density_before": named.evidence_before,
                "loo_log_density_after": named.evidence_after,
                "not_offered": named.excluded.iter().map(|(w, why)| serde_json::json!({"effect": w, "why": why})).collect::<Vec<_>>(),
            });
        }
        if let Some(u) = &updated {
            v["update"] = update_json(u, args.out.as_deref());
        }
        let text = serde_json::to_string_pretty(&v).map_err(Error::JsonOutput)?;
        crate::cli::write_atomically(path, text.as_bytes())?;
    }
    if let Some(path) = &args.log {
        // `cbd report --checks` draws these lines (report::checks): the floor and the top of its
        // band (the largest mean error still at the floor over these rows) beside the error.
        let line = serde_json::json!({
            "time": crate::report::checks::utc_text(now_seconds()),
            "blob": args.blob.display().to_string(),
            "data": args.data.display().to_string(),
            "p_value": s.p_value,
            "mean_error": after.mean,
            "verdict": result.verdict,
            "statistic": s.statistic,
            "dof": s.dof,
            "alpha": args.alpha,
            "rows": data.len(),
            "unit": unit,
            "floor": floor.mean_error,
            "floor_limit": floor.at_floor_limit(data.len()),
            "changes": named.as_ref().map_or_else(Vec::new, |n| n.changes.iter().map(|c| c.to_json()).collect::<Vec<_>>()),
        });
        append_line(path, &line.to_string())?;
    }
    if result.verdict == Verdict::Changed {
        crate::cli::set_exit_code(3);
    }
    Ok(())
}

fn name_error(e: crate::evaluation::check::name::NameError) -> &'static str {
    use crate::evaluation::check::name::NameError;
    match e {
        NameError::NotDhChain => "the library's changes are those of a DH chain measured in 3-D",
        NameError::NotPositiveDefinite => "the fit of the library's changes is not defined on these rows",
    }
}

/// The update's lines: each group refitted, and the error before and after on held-out poses.
fn print_update(u: &crate::evaluation::check::update::Updated, unit: &str) {
    for (group, values) in &u.changes {
        let shown: Vec<String> = values.iter().map(|v| format!("{v:.4e}")).collect();
        outln!("updated: {} by {}", group.spelling(), shown.join(", "));
    }
    outln!(
        "update, mean error at the fresh poses held out of it ({} contiguous blocks): {:.4e} → {:.4e} {unit} (in sample {:.4e})",
        u.blocks,
        u.before,
        u.held_out,
        u.in_sample
    );
}

fn update_json(u: &crate::evaluation::check::update::Updated, out: Option<&Path>) -> serde_json::Value {
    serde_json::json!({
        "out": out.map(|p| p.display().to_string()),
        "parent_sha256": u.parent,
        "groups": u.changes.iter().map(|(g, v)| serde_json::json!({"effect": g.spelling(), "values": v})).collect::<Vec<_>>(),
        "before": u.before,
        "after": u.held_out,
        "after_in_sample": u.in_sample,
        "held_out_blocks": u.blocks,
    })
}

/// Appends `line` and a newline to `path` (made when missing).
fn append_line(path: &Path, line: &str) -> Result<()> {
    use std::io::Write;
    let mut file = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(path)
        .map_err(|e| Error::InvalidInput(format!("{}: {e}", path.display())))?;
    writeln!(file, "{line}").map_err(|e| Error::InvalidInput(format!("{}: {e}", path.display())))
}

/// Seconds since the Unix epoch, now.
fn now_seconds() -> i64 {
    std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_secs()) as i64
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn p_is_printed_as_the_verdict_shows_it() {
        assert_eq!(p_text(0.4125), "0.41");
        assert_eq!(p_text(3.2e-9), "3e-9");
    }
}

//! `cbd check`: does the calibration on the controller still hold? Fresh poses against the blob's
//! own posterior predictive distribution ([`crate::face::check`], docs/DESIGN.md "cbd check"); exit 0
//! when it holds, 3 when it changed (docs/EXIT_CODES.md).

use crate::cli::blob_rows::decode_fitting;
use crate::cli::{ArmModel, ModelArgs};
use crate::error::{Error, Result};
use crate::evaluation::check::Verdict;
use crate::face::{CheckSettings, Checked, DecodedBlob};
use crate::report::checks::p_text;
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
    let settings = CheckSettings { alpha: args.alpha, register: args.register, update: args.update };
    settings.validate()?;
    crate::io::check_paths(
        &[("--model", args.model.model.as_deref()), ("--blob", Some(&args.blob)), ("--data", Some(&args.data))],
        &[("--json", args.json.as_deref()), ("--log", args.log.as_deref()), ("--out", args.out.as_deref())],
    )?;
    let arm = ArmModel::read(&args.model)?;
    let data = crate::face::Dataset::read(&args.data, &arm.spec)?;
    let bytes = crate::face::read_blob(&args.blob)?;
    let model = decode_fitting(&bytes, &args.blob, &args.model, &arm.nominal, &arm.spec)?;
    let checked = crate::face::check(&arm, DecodedBlob { model, source: &args.blob }, &bytes, &data, &settings)?;
    print_checked(&checked, &args.data);
    let updated = match (&args.out, &checked.updated) {
        (_, Some(Err(why))) => return Err(Error::InvalidInput(why.clone())),
        (Some(out), None) => {
            outln!("--update: the calibration holds; {} is not written", out.display());
            None
        }
        (Some(out), Some(Ok(updated))) => {
            print_update(updated, checked.unit);
            crate::cli::write_atomically(out, &updated.blob)?;
            outln!("wrote {} ({} bytes; parent {})", out.display(), updated.blob.len(), &updated.parent[..16]);
            Some(updated)
        }
        (None, _) => None,
    };
    if checked.extrapolating > 0 {
        errln!(
            "warning: {} of {} configurations are far from every measured configuration (kernel support < {}): extrapolation",
            checked.extrapolating,
            checked.rows,
            crate::face::EXTRAPOLATION_THRESHOLD
        );
    }
    if let Some(path) = &args.json {
        let out = updated.and(args.out.as_deref());
        let text = serde_json::to_string_pretty(&checked.to_json(out)).map_err(Error::JsonOutput)?;
        crate::cli::write_atomically(path, text.as_bytes())?;
    }
    if let Some(path) = &args.log {
        let time = crate::report::checks::utc_text(now_seconds());
        let line = checked.log_line(&time, &args.blob.display().to_string(), &args.data.display().to_string());
        append_line(path, &line.to_string())?;
    }
    if checked.result.verdict == Verdict::Changed {
        crate::cli::set_exit_code(3);
    }
    Ok(())
}

/// The check's lines: the frame registered, the error against the floor, the statistic and its
/// verdict, and the named change.
fn print_checked(checked: &Checked, data: &Path) {
    let (result, unit) = (&checked.result, checked.unit);
    if let Some(frame) = &result.frame {
        outln!(
            "{}: frame registered ({} dof, projected out of the test): {}",
            data.display(),
            crate::evaluation::check::register::FRAME_DOF,
            frame.describe(unit)
        );
    }
    let after = &checked.calibrated;
    outln!("{:<12} {:>11} {:>11} {:>11} {:>11}   / floor", "model", "mean", "median", "p99", "max");
    outln!(
        "{:<12} {:>11.4e} {:>11.4e} {:>11.4e} {:>11.4e} {:>9}",
        "calibrated",
        after.mean,
        after.median,
        after.p99,
        after.max,
        checked.floor_verdict.cell()
    );
    outln!("{}; calibrated: {}", checked.floor.describe(unit), checked.floor_verdict.describe());
    let s = &result.statistic;
    let p = p_text(s.p_value);
    outln!(
        "statistic {:.4} on {} degrees of freedom (χ², the blob's predictive covariance at {} rows{}): p = {p}",
        s.statistic,
        s.dof,
        checked.rows,
        if checked.with_drift { " with its recorded drift" } else { "" }
    );
    let verdict = match result.verdict {
        Verdict::Holds => "holds",
        Verdict::Changed => "changed",
    };
    outln!("{verdict} (p = {p}) at alpha = {}", checked.alpha);
    let Some(named) = &checked.named else { return };
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
            if a.p_value < checked.alpha { "more changed than this" } else { "explained" }
        );
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

//! `cbd eval`: evaluate a blob on measured data and report the position error.

use crate::cli::blob_rows::decode_fitting;
use crate::cli::{ArmModel, ModelArgs};
use crate::error::{Error, Result};
use crate::report::stats::ErrorStats;
use std::path::PathBuf;

#[derive(Debug, clap::Args)]
pub struct EvalArgs {
    #[command(flatten)]
    pub model: ModelArgs,
    /// The calibrated model.
    #[arg(long)]
    pub blob: PathBuf,
    /// Measurements to evaluate on (CSV).
    #[arg(long)]
    pub data: PathBuf,
    /// Warn about configurations whose kernel support (max K_V(q, x_j)/γ) is below this.
    #[arg(long, default_value_t = 0.05)]
    pub extrapolation_threshold: f64,
    /// Write figures (error histograms; heatmaps for two-joint arms) into this directory.
    #[arg(long)]
    pub plots: Option<PathBuf>,
    /// Write the error statistics as JSON here (keys `nominal`, `calibrated`, `rows`, `extrapolating`).
    #[arg(long)]
    pub json: Option<PathBuf>,
}

pub fn run(args: EvalArgs) -> Result<()> {
    // Kernel support max K_V(q, x_j)/γ lies in [0, 1]; NaN would silently disable the warning.
    let t = args.extrapolation_threshold;
    if !(0.0..=1.0).contains(&t) {
        return Err(Error::InvalidInput(format!("--extrapolation-threshold must be a number in [0, 1], got {}", crate::error::number(t))));
    }
    crate::io::check_paths(
        &[("--model", args.model.model.as_deref()), ("--blob", Some(&args.blob)), ("--data", Some(&args.data))],
        &[("--json", args.json.as_deref())],
    )?;
    if let Some(dir) = &args.plots {
        crate::io::check_output_dir("--plots", dir)?;
    }
    let arm = ArmModel::read(&args.model)?;
    let imported = crate::data::csv_import::read_measurements(&args.data, &arm.spec)?;
    let data = crate::face::Dataset { source: args.data.clone(), imported };
    let bytes = crate::face::read_blob(&args.blob)?;
    let model = decode_fitting(&bytes, &args.blob, &args.model, &arm.nominal, &arm.spec)?;
    let blob = crate::face::DecodedBlob { model, source: &args.blob };
    let e = crate::face::evaluate(&arm, blob, &data, args.extrapolation_threshold)?;
    let data = &data.imported.measurements;
    let verdict = |s: &ErrorStats| e.noise_floor.as_ref().map(|f| f.verdict(s.mean, e.rows));
    outln!(
        "{:<12} {:>11} {:>11} {:>11} {:>11}{}",
        "model",
        "mean",
        "median",
        "p99",
        "max",
        if e.noise_floor.is_some() { "   / floor" } else { "" }
    );
    for (name, s) in [("nominal", e.nominal), ("calibrated", e.calibrated)] {
        let cell = verdict(&s).map_or(String::new(), |v| format!(" {:>9}", v.cell()));
        outln!("{:<12} {:>11.4e} {:>11.4e} {:>11.4e} {:>11.4e}{cell}", name, s.mean, s.median, s.p99, s.max);
    }
    let unit = arm.length_unit();
    match (&e.noise_floor, verdict(&e.calibrated)) {
        (Some(f), Some(v)) => outln!("{}; calibrated: {}", f.describe(unit), v.describe()),
        _ => outln!("noise floor: unknown ({} records no noise σ: a blob of format 6 or older)", args.blob.display()),
    }
    if let Some((d, with)) = &e.drift {
        outln!(
            "the calibration's rows drifted in measurement order (sd {:.3e} {unit} over {:.1} poses, not in σ): rows measured at \
             another time carry it, a perfect model's mean error {:.4e} {unit} with it; calibrated: {:.2} × that",
            d.sd,
            d.length,
            with.mean_error,
            e.calibrated.mean / with.mean_error
        );
    }
    if e.poses[0].1.is_some() {
        outln!("\nper tool point (mean) and the tool frame (its origin; orientation in degrees):");
        for (name, pose) in &e.poses {
            let Some(pose) = pose else { continue };
            let points: Vec<String> = pose.per_point.iter().enumerate().map(|(j, s)| format!("point {} {:.4e}", j + 1, s.mean)).collect();
            let frame = match (&pose.frame_position, &pose.orientation_deg, pose.orientation_rms_deg) {
                (Some(f), Some(o), Some(rms)) => format!("; frame {:.4e}, orientation mean {:.4e} rms {rms:.4e}", f.mean, o.mean),
                _ => String::new(),
            };
            outln!("{name:<12} {}{frame}", points.join(", "));
        }
    }
    if let Some(path) = &args.json {
        let text = serde_json::to_string_pretty(&e.to_json()).map_err(Error::JsonOutput)?;
        crate::cli::write_atomically(path, text.as_bytes())?;
    }
    if let Some(dir) = &args.plots {
        use crate::report::plots::{error_heatmaps, error_histograms, position_errors};
        let m = data.task_dim;
        let (before, after) =
            (position_errors(&e.nominal_positions, &data.positions, m), position_errors(&e.calibrated_positions, &data.positions, m));
        let unit = "data length unit";
        let mut files = error_histograms(dir, &before, &after, unit)?;
        if data.n_joints == 2 {
            let pairs: Vec<(f64, f64)> = data.joints.chunks_exact(2).map(|q| (q[0], q[1])).collect();
            files.extend(error_heatmaps(dir, "q1 (rad)", "q2 (rad)", &pairs, &before, &after, 24, unit)?);
        }
        outln!("figures written to {} ({} files)", dir.display(), files.len());
    }
    if e.extrapolating > 0 {
        errln!(
            "warning: {} of {} configurations are far from every measured configuration (kernel support < {}): extrapolation",
            e.extrapolating,
            e.rows,
            args.extrapolation_threshold
        );
    }
    Ok(())
}

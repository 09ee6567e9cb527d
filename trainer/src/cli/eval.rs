//! `cbd eval`: evaluate a blob on measured data and report the position error.

use crate::cli::blob_rows::{decode_fitting, evaluate_rows, finite_statistics, recorded_sigma};
use crate::cli::{ArmModel, ModelArgs};
use crate::error::{Context, Error, Result};
use crate::report::noise_floor::NoiseFloor;
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
    let (mut nominal, spec) = (arm.nominal.clone(), &arm.spec);
    let imported = crate::data::csv_import::read_measurements(&args.data, spec)?;
    let (data, lines) = (imported.measurements, imported.lines);
    let blob = crate::data::read_capped(&args.blob, crate::data::MAX_BLOB_BYTES, "blob")?;
    let model = decode_fitting(&blob, &args.blob, &args.model, &nominal, spec)?;
    take_registered_base(&args, &arm, &mut nominal, &model.nominal, &data)?;
    if model.nominal != nominal {
        errln!(
            "note: {} carries its own nominal model (e.g. DH-calibrated); errors are reported against the model file's nominal",
            args.blob.display()
        );
    }
    if model.n_joints() != data.n_joints || model.task_dim() != data.task_dim {
        return Err(Error::InvalidInput(format!(
            "{}: the model has {} joints and {}-D positions, but {} has {} joints and {}-D positions",
            args.blob.display(),
            model.n_joints(),
            model.task_dim(),
            args.data.display(),
            data.n_joints,
            data.task_dim
        )));
    }
    let m = model.task_dim();
    let mut storage = vec![0.0; cbd_runtime::storage_len_for(&model)];
    let mut cal = cbd_runtime::Calibrator::from_model(model, &mut storage).context(args.blob.display())?;
    crate::predict::check_calibrator(&mut cal).context(args.blob.display())?;
    let tool_points = cal.model().nominal.tool_points().to_vec();
    let (predicted, far) = evaluate_rows(&mut cal, &data, &lines, &args.blob, &args.data, args.extrapolation_threshold)?;
    let nominal_pred = crate::nominal::positions(&nominal, &data.joints, m);
    let before = finite_statistics("nominal", &nominal_pred, &data.positions, m, &lines, &args.data)?;
    let after = finite_statistics("calibrated", &predicted, &data.positions, m, &lines, &args.data)?;
    // The σ the calibration assumed, which the blob records (format 7; older blobs: no floor).
    let floor = recorded_sigma(cal.model(), &args.blob)?.map(|sigma| NoiseFloor::new(sigma, m, "the calibration's, recorded in the blob"));
    let verdict = |s: &ErrorStats| floor.as_ref().map(|f| f.verdict(s.mean, data.len()));
    outln!(
        "{:<12} {:>11} {:>11} {:>11} {:>11}{}",
        "model",
        "mean",
        "median",
        "p99",
        "max",
        if floor.is_some() { "   / floor" } else { "" }
    );
    for (name, s) in [("nominal", before), ("calibrated", after)] {
        let cell = verdict(&s).map_or(String::new(), |v| format!(" {:>9}", v.cell()));
        outln!("{:<12} {:>11.4e} {:>11.4e} {:>11.4e} {:>11.4e}{cell}", name, s.mean, s.median, s.p99, s.max);
    }
    match (&floor, verdict(&after)) {
        (Some(f), Some(v)) => outln!("{}; calibrated: {}", f.describe(spec.model_length_unit.name()), v.describe()),
        _ => outln!("noise floor: unknown ({} records no noise σ: a blob of format 6 or older)", args.blob.display()),
    }
    // The drift the calibration's rows carried (format 8): not in σ, but in the error of rows
    // measured at another time, as these may be.
    let drift = cal.model().drift.zip(cal.model().noise_sigma).map(|(d, sigma)| {
        let with = NoiseFloor::new((sigma * sigma + d.sd * d.sd).sqrt(), m, "σ and the calibration's drift, recorded in the blob");
        (d, with)
    });
    if let Some((d, with)) = &drift {
        let unit = spec.model_length_unit.name();
        outln!(
            "the calibration's rows drifted in measurement order (sd {:.3e} {unit} over {:.1} poses, not in σ): rows measured at \
             another time carry it, a perfect model's mean error {:.4e} {unit} with it; calibrated: {:.2} × that",
            d.sd,
            d.length,
            with.mean_error,
            after.mean / with.mean_error
        );
    }
    use crate::evaluation::pose_errors::PoseErrors;
    let poses = [("nominal", &nominal_pred), ("calibrated", &predicted)]
        .map(|(name, p)| (name, PoseErrors::of(&tool_points, p, &data.positions, m)));
    if poses[0].1.is_some() {
        outln!("\nper tool point (mean) and the tool frame (its origin; orientation in degrees):");
        for (name, pose) in &poses {
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
        let pose_json = |k: usize| poses[k].1.as_ref().map(PoseErrors::to_json);
        let mut v = serde_json::json!({"rows": data.len(), "extrapolating": far, "nominal": before, "calibrated": after});
        if let Some(f) = &floor {
            v["noise_floor"] = serde_json::json!({"floor": f, "nominal": verdict(&before), "calibrated": verdict(&after)});
        }
        if let Some((d, with)) = &drift {
            v["drift"] =
                serde_json::json!({"sd": d.sd, "length": d.length, "floor": with, "calibrated": with.verdict(after.mean, data.len())});
        }
        if poses[0].1.is_some() {
            v["pose"] = serde_json::json!({"nominal": pose_json(0), "calibrated": pose_json(1)});
        }
        let text = serde_json::to_string_pretty(&v).map_err(Error::JsonOutput)?;
        crate::cli::write_atomically(path, text.as_bytes())?;
    }
    if let Some(dir) = &args.plots {
        use crate::report::plots::{error_heatmaps, error_histograms, position_errors};
        let (before, after) = (position_errors(&nominal_pred, &data.positions, m), position_errors(&predicted, &data.positions, m));
        let unit = "data length unit";
        let mut files = error_histograms(dir, &before, &after, unit)?;
        if data.n_joints == 2 {
            let pairs: Vec<(f64, f64)> = data.joints.chunks_exact(2).map(|q| (q[0], q[1])).collect();
            files.extend(error_heatmaps(dir, "q1 (rad)", "q2 (rad)", &pairs, &before, &after, 24, unit)?);
        }
        outln!("figures written to {} ({} files)", dir.display(), files.len());
    }
    if far > 0 {
        errln!(
            "warning: {far} of {} configurations are far from every measured configuration (kernel support < {}): extrapolation",
            data.len(),
            args.extrapolation_threshold
        );
    }
    Ok(())
}

/// A base declared unknown was registered when the blob was fitted, on its training rows: the
/// nominal row uses that base (joint 1's constant part folded in when the blob's chain is
/// DH-calibrated), never one registered on the rows being evaluated.
fn take_registered_base(
    args: &EvalArgs,
    arm: &ArmModel,
    nominal: &mut cbd_protocol::NominalModel,
    fitted: &cbd_protocol::NominalModel,
    data: &crate::data::Measurements,
) -> Result<()> {
    let (Some(path), true) = (&arm.path, arm.register_base()) else { return Ok(()) };
    let (cbd_protocol::NominalModel::DhChain(chain), cbd_protocol::NominalModel::DhChain(fitted)) = (&mut *nominal, fitted) else {
        return Err(Error::InvalidInput(format!(
            "{}: the base is declared unknown but {} holds no DH chain to take the registered base from",
            path.display(),
            args.blob.display()
        )));
    };
    let rms_before = crate::parametric::base_registration::rms_from(chain, data);
    let base = crate::parametric::base_registration::folded_base(chain, fitted);
    chain.base = base.to_transform();
    let r = crate::parametric::base_registration::Registration {
        base,
        rms_before,
        rms_after: crate::parametric::base_registration::rms_from(chain, data),
        refined: true,
        stopped_at_limit: None,
    };
    errln!("{}: {} (as fitted, from {})", args.data.display(), r.describe(arm.length_unit()), args.blob.display());
    Ok(())
}

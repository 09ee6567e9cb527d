//! `cbd eval`: evaluate a blob on measured data and report the position error.

use crate::cli::{load_nominal, ModelArgs};
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

pub fn run(args: EvalArgs) -> Result<(), String> {
    if let Some(path) = &args.json {
        crate::cli::check_output_dir(path)?;
    }
    let (nominal, spec) = load_nominal(&args.model)?;
    let imported = crate::data::csv_import::read_measurements(&args.data, &spec).map_err(|e| e.to_string())?;
    let (data, lines) = (imported.measurements, imported.lines);
    let blob = std::fs::read(&args.blob).map_err(|e| format!("{}: {e}", args.blob.display()))?;
    let model = cbd_protocol::decode(&blob).map_err(|e| format!("{}: {e}", args.blob.display()))?;
    if model.nominal != nominal {
        eprintln!(
            "note: {} carries its own nominal model (e.g. DH-calibrated); errors are reported against the model file's nominal",
            args.blob.display()
        );
    }
    if model.n_joints() != data.n_joints || model.task_dim() != data.task_dim {
        return Err(format!(
            "{}: the model has {} joints and {}-D positions, but {} has {} joints and {}-D positions",
            args.blob.display(),
            model.n_joints(),
            model.task_dim(),
            args.data.display(),
            data.n_joints,
            data.task_dim
        ));
    }
    let m = model.task_dim();
    let mut storage = vec![0.0; cbd_runtime::storage_len(model.n_points as usize, model.n_joints(), m, model.integrator)];
    let mut cal = cbd_runtime::Calibrator::from_model(model, &mut storage).map_err(|e| format!("{}: {e}", args.blob.display()))?;
    let mut predicted = Vec::with_capacity(data.positions.len());
    let mut nominal_pred = Vec::with_capacity(data.positions.len());
    let mut far = 0;
    for i in 0..data.len() {
        let line = lines.get(i).copied().unwrap_or(0);
        let e = cal.evaluate(data.joints(i)).map_err(|e| format!("{}:{line}: {e}", args.data.display()))?;
        if e.is_extrapolating(args.extrapolation_threshold) {
            far += 1;
        }
        predicted.extend(e.position().iter());
        nominal_pred.extend_from_slice(&cbd_runtime::nominal::forward_kinematics(&nominal, data.joints(i)).position[..m]);
    }
    let before = ErrorStats::of_positions(&nominal_pred, &data.positions, m);
    let after = ErrorStats::of_positions(&predicted, &data.positions, m);
    println!("{:<12} {:>11} {:>11} {:>11} {:>11}", "model", "mean", "median", "p99", "max");
    for (name, s) in [("nominal", before), ("calibrated", after)] {
        println!("{:<12} {:>11.4e} {:>11.4e} {:>11.4e} {:>11.4e}", name, s.mean, s.median, s.p99, s.max);
    }
    if let Some(path) = &args.json {
        let v = serde_json::json!({"rows": data.len(), "extrapolating": far, "nominal": before, "calibrated": after});
        let text = serde_json::to_string_pretty(&v).map_err(|e| e.to_string())?;
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
        println!("figures written to {} ({} files)", dir.display(), files.len());
    }
    if far > 0 {
        eprintln!(
            "warning: {far} of {} configurations are far from every measured configuration (kernel support < {}): extrapolation",
            data.len(),
            args.extrapolation_threshold
        );
    }
    Ok(())
}

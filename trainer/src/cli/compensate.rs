//! `cbd compensate`: joint commands that put the calibrated arm's tool at Cartesian targets
//! (`Calibrator::compensate`: damped minimum-norm Gauss–Newton on the exact Jacobian of k1 from a
//! seed, the nominal model's inverse kinematics), with the residual and flags of every row.

use crate::cli::{load_nominal, ModelArgs};
use crate::data::csv_import::ColumnSpec;
use crate::error::{Context, Error, Result};
use crate::evaluation::compensation::{compensate_all, compensate_all_poses, CompensateError};
use cbd_protocol::JointKind;
use cbd_runtime::Compensation;
use std::path::{Path, PathBuf};

#[derive(Debug, clap::Args)]
pub struct CompensateArgs {
    #[command(flatten)]
    pub model: ModelArgs,
    /// The calibrated model.
    #[arg(long)]
    pub blob: PathBuf,
    /// Targets (CSV with the model file's position columns, e.g. x, y or x_mm, y_mm, z_mm).
    #[arg(long)]
    pub targets: PathBuf,
    /// Seeds, one row per target (CSV with the model file's joint columns): where the nominal
    /// inverse kinematics starts; with more joints than task coordinates, the command keeps the
    /// seed's redundant coordinates (orientation) and branch. Without: the training configuration
    /// whose nominal position is nearest the target.
    #[arg(long)]
    pub seeds: Option<PathBuf>,
    /// Joint commands (CSV: the joint columns in the file's units, then `residual` in the file's
    /// length unit and `flags`: `ok`, or `not_reached`, `singular`, `extrapolating` joined by `+`).
    #[arg(long)]
    pub out: PathBuf,
    /// Write a summary as JSON here (rows, reached, singular, extrapolating, residual statistics).
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Gauss–Newton steps on the calibrated model (fixed: the cost is the same for every target).
    /// More than the runtime's default of 3 (`CompensateOptions::for_model`, sized for a control
    /// cycle): on the host accuracy comes first, and trained models whose momenta cancel (the RR
    /// demo's) need more than 3 steps from the inverse-flow start to reach their own precision.
    #[arg(long, default_value_t = 8)]
    pub iterations: usize,
    /// Largest residual (the file's length unit) counted as reached; default 1e-9 of the model's
    /// task scale (the RMS radius of its training positions).
    #[arg(long)]
    pub tolerance: Option<f64>,
}

/// The columns of a file of targets: `spec`'s positions alone, at least one row.
/// With at least 3 tool points the targets are poses (their points, or position + orientation
/// columns, read as the points: `pose_targets`).
fn targets_spec(spec: &ColumnSpec) -> ColumnSpec {
    let poses = spec.tool_points.len() >= 3;
    ColumnSpec {
        joint_columns: Vec::new(),
        joint_kinds: Vec::new(),
        joint_limits: Vec::new(),
        min_rows: 1,
        joint_map: None,
        tool_points: if poses { spec.tool_points.clone() } else { Vec::new() },
        orientation_columns: if poses { spec.orientation_columns.clone() } else { None },
        ..spec.clone()
    }
}

/// Target poses (docs/DESIGN.md §12): each target row's tool points (as read: the point columns,
/// or p + R p_j of a pose's columns) and their least-squares tool frame, the target the runtime's
/// `Calibrator::compensate_pose` takes; with the file lines.
fn pose_targets(path: &Path, spec: &ColumnSpec) -> Result<(Vec<crate::nominal::Frame>, Vec<u64>)> {
    let imported = crate::data::csv_import::read_measurements(path, &targets_spec(spec))?;
    let data = &imported.measurements;
    let p = data.points_per_pose;
    let mut frames = Vec::with_capacity(data.pose_count());
    for k in 0..data.pose_count() {
        let points: Vec<[f64; 3]> = (0..p).map(|j| std::array::from_fn(|c| data.position(k * p + j)[c])).collect();
        let frame = crate::nominal::tool_points::tool_frame(&spec.tool_points, &points).ok_or_else(|| Error::AtLine {
            file: path.to_path_buf(),
            line: imported.lines[k * p],
            message: "the target's tool points determine no frame (on a line?)".into(),
        })?;
        frames.push(frame);
    }
    Ok((frames, imported.lines.iter().step_by(p.max(1)).copied().collect()))
}

/// The flags column of a pose command.
fn pose_flags(c: &cbd_runtime::PoseCompensation) -> String {
    flags(&Compensation {
        residual: c.position_residual,
        reached: c.reached,
        singular: c.singular,
        extrapolating: c.extrapolating,
        support: c.support,
        conditioning: c.conditioning,
    })
}

/// The columns of a file of seeds: `spec`'s joints alone (in their ranges), at least one row.
fn seeds_spec(spec: &ColumnSpec) -> ColumnSpec {
    ColumnSpec { position_columns: Vec::new(), min_rows: 1, tool_points: Vec::new(), orientation_columns: None, ..spec.clone() }
}

/// The rows of `path` read as measurement files are (`csv_import`: the size and line caps, the
/// field count, numbers finite and within ±1e100 in the model's unit, joints in their ranges,
/// errors naming the file, line and column), in the model's units, with their file lines.
fn read_rows(path: &Path, spec: &ColumnSpec) -> Result<(Vec<Vec<f64>>, Vec<u64>)> {
    let imported = crate::data::csv_import::read_measurements(path, spec)?;
    let data = &imported.measurements;
    let row = |i: usize| if data.n_joints > 0 { data.joints(i).to_vec() } else { data.position(i).to_vec() };
    Ok(((0..data.len()).map(row).collect(), imported.lines))
}

/// Per joint column: the factor from the file's unit to the model's (radians or model length).
fn joint_scales(spec: &ColumnSpec) -> Vec<f64> {
    spec.joint_kinds
        .iter()
        .map(|k| match k {
            JointKind::Revolute => spec.angle_unit.radians(),
            JointKind::Prismatic => spec.length_unit.factor_to(spec.model_length_unit),
        })
        .collect()
}

/// The flags column: `ok`, or what is wrong joined by `+`.
pub fn flags(c: &Compensation) -> String {
    let mut out = Vec::new();
    if !c.reached {
        out.push("not_reached");
    }
    if c.singular {
        out.push("singular");
    }
    if c.extrapolating {
        out.push("extrapolating");
    }
    if out.is_empty() {
        "ok".into()
    } else {
        out.join("+")
    }
}

pub fn run(args: CompensateArgs) -> Result<()> {
    crate::io::check_paths(
        &[
            ("--model", args.model.model.as_deref()),
            ("--blob", Some(&args.blob)),
            ("--targets", Some(&args.targets)),
            ("--seeds", args.seeds.as_deref()),
        ],
        &[("--out", Some(&args.out)), ("--json", args.json.as_deref())],
    )?;
    if args.iterations == 0 || args.iterations > 64 {
        return Err(Error::InvalidInput(format!("--iterations must be between 1 and 64, got {}", args.iterations)));
    }
    if let Some(t) = args.tolerance {
        if !(t > 0.0 && t.is_finite()) {
            return Err(Error::InvalidInput(format!("--tolerance must be a positive finite length, got {t}")));
        }
    }
    let (nominal, spec) = load_nominal(&args.model)?;
    let blob = crate::data::read_capped(&args.blob, crate::data::MAX_BLOB_BYTES, "blob")?;
    let model = cbd_protocol::decode(&blob).context(args.blob.display())?;
    if model.n_joints() != nominal.n_joints() || model.task_dim() != nominal.task_dim() {
        let arm = if args.model.model.is_some() { "the model file's arm" } else { "the built-in RR arm (no --model given)" };
        return Err(Error::InvalidInput(format!(
            "{}: the model has {} joints and {}-D positions, but {arm} has {} joints and {}-D positions",
            args.blob.display(),
            model.n_joints(),
            model.task_dim(),
            nominal.n_joints(),
            nominal.task_dim()
        )));
    }
    let length = spec.length_unit.factor_to(spec.model_length_unit);
    if spec.tool_points.len() >= 3 {
        return run_poses(&args, &spec, &blob, length);
    }
    let (targets, target_lines) = read_rows(&args.targets, &targets_spec(&spec))?;
    let seeds = match &args.seeds {
        Some(path) => {
            let (seeds, _) = read_rows(path, &seeds_spec(&spec))?;
            if seeds.len() != targets.len() {
                return Err(Error::InvalidInput(format!(
                    "{}: {} seed rows for {} target rows in {} (one seed per target)",
                    path.display(),
                    seeds.len(),
                    targets.len(),
                    args.targets.display()
                )));
            }
            Some(seeds)
        }
        None => None,
    };
    let tolerance = args.tolerance.map(|t| t * length);
    let rows = compensate_all(&blob, &targets, seeds.as_deref(), args.iterations, tolerance).map_err(|e| match e {
        CompensateError::Model(e) => e.context(args.blob.display().to_string()),
        CompensateError::Row { row, message } => Error::AtLine { file: args.targets.clone(), line: target_lines[row], message },
    })?;
    let (joint_scale, unit) = (joint_scales(&spec), spec.length_unit.name());
    let mut text = format!("{},residual,flags\n", spec.joint_columns.join(","));
    for r in &rows {
        let mut joints = r.joints.clone();
        if let Some(frame) = &spec.planar_frame {
            // The chain's joints back to the arm's (the import added the offsets).
            joints.iter_mut().zip(&frame.offsets).for_each(|(q, o)| *q -= o);
        }
        let mut columns: Vec<f64> = joints.iter().zip(&joint_scale).map(|(v, s)| v / s).collect();
        if let Some(map) = &spec.joint_map {
            // Model joints back to the controller's values (the inverse of the import's mapping).
            let model = columns.clone();
            map.to_columns(&model, &mut columns);
        }
        let q: Vec<String> = columns.iter().map(|v| format!("{v:?}")).collect();
        text.push_str(&format!("{},{:?},{}\n", q.join(","), r.compensation.residual / length, flags(&r.compensation)));
    }
    crate::cli::write_atomically(&args.out, text.as_bytes())?;
    let count = |f: &dyn Fn(&Compensation) -> bool| rows.iter().filter(|r| f(&r.compensation)).count();
    let residuals: Vec<f64> = rows.iter().map(|r| r.compensation.residual / length).collect();
    let stats = crate::report::stats::ErrorStats::of_errors(&residuals);
    let (reached, singular, extrapolating) = (count(&|c| c.reached), count(&|c| c.singular), count(&|c| c.extrapolating));
    errln!(
        "{} targets: {reached} reached, {singular} singular, {extrapolating} outside the calibrated region; residual median {:.3e} max {:.3e} {unit}",
        rows.len(),
        stats.median,
        stats.max
    );
    if let Some(path) = &args.json {
        let json = serde_json::json!({
            "rows": rows.len(), "reached": reached, "singular": singular, "extrapolating": extrapolating,
            "iterations": args.iterations, "unit": unit,
            "residual": {"mean": stats.mean, "median": stats.median, "p99": stats.p99, "max": stats.max},
        });
        let text = serde_json::to_string_pretty(&json).map_err(Error::JsonOutput)?;
        crate::cli::write_atomically(path, text.as_bytes())?;
    }
    Ok(())
}

/// `cbd compensate` with target poses (a model file with ≥ 3 tool points): the joint columns, then
/// `position_residual` (length unit), `angle_residual` (degrees) and `flags`.
fn run_poses(args: &CompensateArgs, spec: &ColumnSpec, blob: &[u8], length: f64) -> Result<()> {
    let (targets, target_lines) = pose_targets(&args.targets, spec)?;
    let seeds = match &args.seeds {
        Some(path) => Some(read_rows(path, &seeds_spec(spec))?.0),
        None => None,
    };
    if let Some(seeds) = &seeds {
        if seeds.len() != targets.len() {
            return Err(Error::InvalidInput(format!("{} seed rows for {} target poses (one seed per target)", seeds.len(), targets.len())));
        }
    }
    let rows = compensate_all_poses(blob, &targets, seeds.as_deref()).map_err(|e| match e {
        CompensateError::Model(e) => e.context(args.blob.display().to_string()),
        CompensateError::Row { row, message } => Error::AtLine { file: args.targets.clone(), line: target_lines[row], message },
    })?;
    let joint_scale = joint_scales(spec);
    let mut text = format!("{},position_residual,angle_residual_deg,flags\n", spec.joint_columns.join(","));
    for r in &rows {
        let mut columns: Vec<f64> = r.joints.iter().zip(&joint_scale).map(|(v, s)| v / s).collect();
        if let Some(map) = &spec.joint_map {
            let model = columns.clone();
            map.to_columns(&model, &mut columns);
        }
        let q: Vec<String> = columns.iter().map(|v| format!("{v:?}")).collect();
        let c = &r.compensation;
        text.push_str(&format!(
            "{},{:?},{:?},{}\n",
            q.join(","),
            c.position_residual / length,
            c.angle_residual.to_degrees(),
            pose_flags(c)
        ));
    }
    crate::cli::write_atomically(&args.out, text.as_bytes())?;
    let reached = rows.iter().filter(|r| r.compensation.reached).count();
    let position =
        crate::report::stats::ErrorStats::of_errors(&rows.iter().map(|r| r.compensation.position_residual / length).collect::<Vec<_>>());
    let angle =
        crate::report::stats::ErrorStats::of_errors(&rows.iter().map(|r| r.compensation.angle_residual.to_degrees()).collect::<Vec<_>>());
    errln!(
        "{} target poses: {reached} reached; position residual max {:.3e} {}, angle residual max {:.3e}°",
        rows.len(),
        position.max,
        spec.length_unit.name(),
        angle.max
    );
    if let Some(path) = &args.json {
        let json = serde_json::json!({
            "rows": rows.len(), "reached": reached, "unit": spec.length_unit.name(),
            "position_residual": {"mean": position.mean, "median": position.median, "max": position.max},
            "angle_residual_deg": {"mean": angle.mean, "median": angle.median, "max": angle.max},
        });
        let text = serde_json::to_string_pretty(&json).map_err(Error::JsonOutput)?;
        crate::cli::write_atomically(path, text.as_bytes())?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn file(name: &str, text: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("cbd-compensate-test-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join(name);
        std::fs::write(&path, text).unwrap();
        path
    }

    /// Issue 27 item 9: targets and seeds are read as measurement files are (the old reader took
    /// seeds of 1e200, extra fields and targets beyond ±1e100); errors name the file, line and column.
    #[test]
    fn targets_and_seeds_are_read_with_the_importers_rules() {
        let (_, spec) = load_nominal(&ModelArgs { model: None }).unwrap();
        // The error's message, as `cbd` prints it.
        let message = |e: Error| e.to_string();
        let targets = |name: &str, text: &str| read_rows(&file(name, text), &targets_spec(&spec)).map_err(message);
        let seeds = |name: &str, text: &str| read_rows(&file(name, text), &seeds_spec(&spec)).map_err(message);
        let e = targets("a.csv", "x,y\n0.5,0.1\n0.5,abc\n").unwrap_err();
        assert!(e.ends_with("a.csv:3: column 'y': not a number: 'abc'"), "{e}");
        assert!(targets("b.csv", "x,z\n0.5,1\n").unwrap_err().contains("b.csv:1: column 'y': no such column"));
        assert!(targets("c.csv", "x,y\n0.5\n").unwrap_err().contains("c.csv:2: 1 fields; the header has 2"));
        assert!(targets("d.csv", "x,y\n0.5,inf\n").unwrap_err().contains("d.csv:2: column 'y': not a finite number: 'inf'"));
        assert!(targets("e.csv", "x,y\n").unwrap_err().contains("0 data rows"));
        assert!(targets("g.csv", "x,y\n1,2,3\n").unwrap_err().contains("g.csv:2: 3 fields; the header has 2"));
        assert!(targets("h.csv", "x,y\n1e300,0\n")
            .unwrap_err()
            .contains("h.csv:2: column 'x': '1e300' m is 1e300 m; values must stay within ±1e100"));
        assert!(seeds("i.csv", "q1,q2\n1e200,0\n").unwrap_err().contains("i.csv:2: column 'q1': 1e200 rad is outside the joint's range"));
        let (rows, lines) = targets("f.csv", "x,y\n1,2\n\n3,4\n3,4\n").unwrap();
        assert_eq!((rows, lines), (vec![vec![1.0, 2.0], vec![3.0, 4.0], vec![3.0, 4.0]], vec![2, 4, 5]));
        assert_eq!(seeds("s.csv", "q2,q1\n0.5,0.25\n").unwrap().0, vec![vec![0.25, 0.5]]);
    }

    #[test]
    fn commands_reach_reachable_targets_of_a_trained_model() {
        let real = crate::simulate::rr::RealRr::default();
        let train = real.measure(&crate::simulate::configurations(crate::simulate::Sampling::Grid { per_axis: 12 }, 2));
        let settings = crate::calibrate::Settings { verbose: false, ..Default::default() };
        let blob = crate::calibrate::calibrate(&crate::simulate::rr::nominal(), &train, &settings).unwrap().fit.blob;
        let joints = crate::simulate::configurations(crate::simulate::Sampling::Uniform { count: 50, seed: 9 }, 2);
        let targets: Vec<Vec<f64>> = joints.chunks_exact(2).map(|q| crate::predict::evaluate_blob(&blob, q).unwrap()).collect();
        let rows = compensate_all(&blob, &targets, None, 8, None).unwrap();
        for (r, t) in rows.iter().zip(&targets) {
            let y = crate::predict::evaluate_blob(&blob, &r.joints).unwrap();
            let miss = ((y[0] - t[0]).powi(2) + (y[1] - t[1]).powi(2)).sqrt();
            // The fitted RR model is good to about 1e-9 m (its momenta cancel to 1 part in 1e9).
            assert!(miss < 1e-8 && (miss - r.compensation.residual).abs() < 1e-12, "{miss} {:?}", r.compensation.residual);
        }
        // A target out of reach: flagged, finite command.
        let rows = compensate_all(&blob, &[vec![3.0, 0.0]], None, 8, None).unwrap();
        assert!(!rows[0].compensation.reached && rows[0].joints.iter().all(|v| v.is_finite()));
        assert!(flags(&rows[0].compensation).starts_with("not_reached"));
    }
}

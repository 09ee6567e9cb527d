//! `cbd compensate`: joint commands that put the calibrated arm's tool at Cartesian targets
//! (`Calibrator::compensate`: damped minimum-norm Gauss–Newton on the exact Jacobian of k1 from a
//! seed, the nominal model's inverse kinematics), with the residual and flags of every row.

use crate::cli::{ArmModel, ModelArgs};
use crate::data::csv_import::ColumnSpec;
use crate::data::joint_columns::JointColumns;
use crate::error::{Context, Error, Result};
use crate::evaluation::command_check::{check_poses, check_positions, periodic_joints, RowFlags};
use crate::evaluation::compensation::{compensate_all, compensate_all_poses, CompensateError};
use crate::face::MAX_ITERATIONS;
use cbd_protocol::NominalModel;
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
    /// Joint commands (CSV: the joint columns in the file's units — the controller's values, turned
    /// into the joint limits by whole turns where that keeps the pose — then `residual` in the
    /// file's length unit at the command as written, and `flags`: `ok` (finite, inside the joint
    /// limits, reached within the model's precision, orientation determined), or `not_reached`,
    /// `outside_limits`, `degenerate_target`, `singular`, `extrapolating` joined by `+`).
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
/// or p + R p_j of a pose's columns), their least-squares tool frame — the target the runtime's
/// `Calibrator::compensate_pose` takes — and whether the target is degenerate: its points on a
/// line or coincident (no orientation), or not a rigid copy of the tool points (RMS misfit over
/// [`TARGET_MISFIT`] of their lever: a triangle twice the tool's). With the file lines.
fn pose_targets(path: &Path, spec: &ColumnSpec, lever: f64) -> Result<PoseTargets> {
    use cbd_runtime::internals::kinematics::tool_frame::determines_orientation;
    let imported = crate::data::csv_import::read_measurements(path, &targets_spec(spec))?;
    let data = &imported.measurements;
    let p = data.points_per_pose;
    let mut targets = PoseTargets { frames: Vec::new(), degenerate: Vec::new(), lines: Vec::new() };
    for k in 0..data.pose_count() {
        let points: Vec<[f64; 3]> = (0..p).map(|j| std::array::from_fn(|c| data.position(k * p + j)[c])).collect();
        let centroid: [f64; 3] = std::array::from_fn(|c| points.iter().map(|y| y[c]).sum::<f64>() / p as f64);
        let frame = crate::nominal::tool_points::tool_frame(&spec.tool_points, &points)
            .unwrap_or_else(|| crate::nominal::Frame::IDENTITY.with_translation(centroid));
        let misfit = (spec
            .tool_points
            .iter()
            .zip(&points)
            .map(|(t, y)| crate::nominal::norm(crate::nominal::sub(frame.apply(*t), *y)).powi(2))
            .sum::<f64>()
            / p as f64)
            .sqrt();
        targets.degenerate.push(!determines_orientation(&points) || !(misfit <= TARGET_MISFIT * lever));
        targets.frames.push(frame);
        targets.lines.push(imported.lines[k * p]);
    }
    Ok(targets)
}

/// Largest RMS distance of a target's points from the rigid copy of the tool points fitted to them,
/// as a share of the tool points' lever, for a pose target: measurement noise is far below it, a
/// target of another shape far above.
const TARGET_MISFIT: f64 = 0.01;

/// The target poses of a file: frames, degenerate or not, file lines.
struct PoseTargets {
    frames: Vec<crate::nominal::Frame>,
    degenerate: Vec<bool>,
    lines: Vec<u64>,
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
    if args.iterations == 0 || args.iterations > MAX_ITERATIONS {
        return Err(Error::InvalidInput(format!("--iterations must be between 1 and {MAX_ITERATIONS}, got {}", args.iterations)));
    }
    if let Some(t) = args.tolerance {
        if !(t > 0.0 && t <= crate::limits::MAX_MAGNITUDE) {
            return Err(Error::InvalidInput(format!(
                "--tolerance must be a positive finite length within ±1e100, got {}",
                crate::error::number(t)
            )));
        }
    }
    let arm = ArmModel::read(&args.model)?;
    let (nominal, spec) = (arm.nominal.clone(), arm.spec.clone());
    let blob = crate::face::read_blob(&args.blob)?;
    let model = crate::cli::blob_rows::decode_fitting(&blob, &args.blob, &args.model, &nominal, &spec)?;
    let periodic = periodic_joints(&model);
    let length = spec.length_unit.factor_to(spec.model_length_unit);
    if spec.tool_points.len() >= 3 {
        return run_poses(&args, &spec, &nominal, &blob, &periodic, length);
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
    // The commands as written (turned into the limits where a whole turn does it) and as read back.
    let columns = JointColumns::new(&spec);
    let written: Vec<Vec<f64>> = rows.iter().map(|r| columns.within_limits(&r.joints, &periodic)).collect();
    let reread: Vec<Vec<f64>> = written.iter().map(|c| columns.to_model(c)).collect();
    let checks = check_positions(&blob, &reread, &targets, tolerance).context(args.blob.display())?;
    let unit = spec.length_unit.name();
    let mut text = format!("{},residual,flags\n", spec.joint_columns.join(","));
    let mut flags = Vec::with_capacity(rows.len());
    for ((r, c), check) in rows.iter().zip(&written).zip(&checks) {
        let f = RowFlags {
            not_reached: !check.reached,
            outside_limits: columns.limit_excess(c) > 0.0,
            singular: r.compensation.singular,
            extrapolating: r.compensation.extrapolating,
            ..RowFlags::default()
        };
        let q: Vec<String> = c.iter().map(|v| format!("{v:?}")).collect();
        text.push_str(&format!("{},{:?},{}\n", q.join(","), check.residual / length, f.text()));
        flags.push(f);
    }
    crate::cli::write_atomically(&args.out, text.as_bytes())?;
    let residuals: Vec<f64> = checks.iter().map(|c| c.residual / length).collect();
    let stats = crate::report::stats::ErrorStats::of_errors(&residuals);
    let counts = FlagCounts::of(&flags);
    errln!(
        "{} targets: {} ok; {} reached, {} outside the joint limits, {} singular, {} outside the calibrated region; residual median {:.3e} max {:.3e} {unit}",
        rows.len(),
        counts.ok,
        counts.reached,
        counts.outside_limits,
        counts.singular,
        counts.extrapolating,
        stats.median,
        stats.max
    );
    if let Some(path) = &args.json {
        let mut json = counts.to_json(rows.len());
        json["iterations"] = args.iterations.into();
        json["unit"] = unit.into();
        json["tolerance"] = (tolerance.unwrap_or(checks.first().map_or(f64::NAN, |c| c.tolerance)) / length).into();
        json["residual"] = serde_json::json!({"mean": stats.mean, "median": stats.median, "p99": stats.p99, "max": stats.max});
        let text = serde_json::to_string_pretty(&json).map_err(Error::JsonOutput)?;
        crate::cli::write_atomically(path, text.as_bytes())?;
    }
    Ok(())
}

/// How many rows carry each flag, and how many are `ok`.
struct FlagCounts {
    ok: usize,
    reached: usize,
    outside_limits: usize,
    degenerate_target: usize,
    singular: usize,
    extrapolating: usize,
}

impl FlagCounts {
    fn of(flags: &[RowFlags]) -> FlagCounts {
        let count = |f: &dyn Fn(&RowFlags) -> bool| flags.iter().filter(|r| f(r)).count();
        FlagCounts {
            ok: count(&|r| r.is_ok()),
            reached: count(&|r| !r.not_reached),
            outside_limits: count(&|r| r.outside_limits),
            degenerate_target: count(&|r| r.degenerate_target),
            singular: count(&|r| r.singular),
            extrapolating: count(&|r| r.extrapolating),
        }
    }

    fn to_json(&self, rows: usize) -> serde_json::Value {
        serde_json::json!({
            "rows": rows, "ok": self.ok, "reached": self.reached, "outside_limits": self.outside_limits,
            "degenerate_target": self.degenerate_target, "singular": self.singular, "extrapolating": self.extrapolating,
        })
    }
}

/// `cbd compensate` with target poses (a model file with ≥ 3 tool points): the joint columns, then
/// `position_residual` (length unit), `angle_residual_deg` (degrees) and `flags`.
fn run_poses(args: &CompensateArgs, spec: &ColumnSpec, nominal: &NominalModel, blob: &[u8], periodic: &[bool], length: f64) -> Result<()> {
    use cbd_runtime::internals::kinematics::tool_frame::determines_orientation;
    let model_name = args.model.model.as_ref().map_or(String::new(), |p| p.display().to_string());
    if !determines_orientation(&spec.tool_points) {
        return Err(Error::InvalidInput(format!(
            "{model_name}: [chain.tool] points lie on one line: they determine no orientation, so a target pose cannot be reached (compensate positions with a model of one tool point, or add a point off the line)"
        )));
    }
    let targets = pose_targets(&args.targets, spec, cbd_runtime::internals::compensate_pose::tool_lever(nominal))?;
    let seeds = match &args.seeds {
        Some(path) => Some(read_rows(path, &seeds_spec(spec))?.0),
        None => None,
    };
    if let Some(seeds) = &seeds {
        if seeds.len() != targets.frames.len() {
            return Err(Error::InvalidInput(format!(
                "{} seed rows for {} target poses (one seed per target)",
                seeds.len(),
                targets.frames.len()
            )));
        }
    }
    let rows = compensate_all_poses(blob, &targets.frames, seeds.as_deref()).map_err(|e| match e {
        CompensateError::Model(e) => e.context(args.blob.display().to_string()),
        CompensateError::Row { row, message } => Error::AtLine { file: args.targets.clone(), line: targets.lines[row], message },
    })?;
    let columns = JointColumns::new(spec);
    let written: Vec<Vec<f64>> = rows.iter().map(|r| columns.within_limits(&r.joints, periodic)).collect();
    let reread: Vec<Vec<f64>> = written.iter().map(|c| columns.to_model(c)).collect();
    let checks = check_poses(blob, &reread, &targets.frames).context(args.blob.display())?;
    let mut text = format!("{},position_residual,angle_residual_deg,flags\n", spec.joint_columns.join(","));
    let mut flags = Vec::with_capacity(rows.len());
    for (((r, c), check), degenerate) in rows.iter().zip(&written).zip(&checks).zip(&targets.degenerate) {
        let f = RowFlags {
            not_reached: !check.reached,
            outside_limits: columns.limit_excess(c) > 0.0,
            degenerate_target: *degenerate,
            singular: r.compensation.singular,
            extrapolating: r.compensation.extrapolating,
        };
        let q: Vec<String> = c.iter().map(|v| format!("{v:?}")).collect();
        text.push_str(&format!(
            "{},{:?},{:?},{}\n",
            q.join(","),
            check.position_residual / length,
            check.angle_residual.to_degrees(),
            f.text()
        ));
        flags.push(f);
    }
    crate::cli::write_atomically(&args.out, text.as_bytes())?;
    let counts = FlagCounts::of(&flags);
    let position = crate::report::stats::ErrorStats::of_errors(&checks.iter().map(|c| c.position_residual / length).collect::<Vec<_>>());
    let angle = crate::report::stats::ErrorStats::of_errors(&checks.iter().map(|c| c.angle_residual.to_degrees()).collect::<Vec<_>>());
    errln!(
        "{} target poses: {} ok; {} reached, {} outside the joint limits, {} degenerate targets, {} singular, {} outside the calibrated region; position residual max {:.3e} {}, angle residual max {:.3e}°",
        rows.len(),
        counts.ok,
        counts.reached,
        counts.outside_limits,
        counts.degenerate_target,
        counts.singular,
        counts.extrapolating,
        position.max,
        spec.length_unit.name(),
        angle.max
    );
    if let Some(path) = &args.json {
        let mut json = counts.to_json(rows.len());
        json["unit"] = spec.length_unit.name().into();
        json["position_residual"] = serde_json::json!({"mean": position.mean, "median": position.median, "max": position.max});
        json["angle_residual_deg"] = serde_json::json!({"mean": angle.mean, "median": angle.median, "max": angle.max});
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
        let spec = ArmModel::builtin_rr().spec;
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
        let settings = crate::calibrate::Settings::default();
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
        assert!(!rows[0].compensation.reached);
    }
}

//! `cbd plan`: where to measure next — poses within the joint limits, away from singular
//! configurations, chosen for the geometric group's identifiability and then for CbD's posterior
//! variance, with the RMS error the posterior predicts after each (docs/DESIGN.md §13).

use crate::cli::{ArmModel, ModelArgs};
use crate::data::csv_import::{read_measurements, ColumnSpec};
use crate::error::{Context, Error, Result};
use crate::plan::{plan, prior, Criterion, PlanInput, PlanOptions};
use std::path::PathBuf;

#[derive(Debug, clap::Args)]
pub struct PlanArgs {
    #[command(flatten)]
    pub model: ModelArgs,
    /// Poses to plan.
    #[arg(long, required_unless_present = "check")]
    pub count: Option<usize>,
    /// Plan N poses for `cbd check` instead (issue 50 item 5, with --blob): the poses that make the
    /// check most sensitive to the changes it names, and the smallest change of each kind it
    /// detects at --alpha with 90 % power, with N random poses and with the N planned.
    #[arg(long, value_name = "N", requires = "blob", conflicts_with_all = ["count", "data", "candidate_file", "criterion", "exchange"])]
    pub check: Option<usize>,
    /// With --check: the calibrated blob the check tests against.
    #[arg(long, requires = "check")]
    pub blob: Option<PathBuf>,
    /// With --check: the check's level.
    #[arg(long, default_value_t = 0.01)]
    pub alpha: f64,
    /// With --check: plan for a check that registers the fresh rows' frame (`cbd check
    /// --register`; also when the model file's base is `register = true`): the frame's 6 degrees
    /// of freedom are projected out of the sizes, and a base shift is not offered.
    #[arg(long, requires = "check")]
    pub register: bool,
    /// Output CSV of the planned poses: the model file's joint columns in their units (without a
    /// model file q1, q2 in radians), ready for `cbd simulate --poses` or the robot.
    #[arg(long)]
    pub out: PathBuf,
    /// Poses already measured (CSV, as for `cbd fit`): the plan continues from them, and the
    /// hyperparameters come from CbD's evidence on them.
    #[arg(long)]
    pub data: Option<PathBuf>,
    /// Random candidates within the joint limits.
    #[arg(long, default_value_t = 10_000)]
    pub candidates: usize,
    /// Your own candidate poses (CSV with the model's joint columns), considered besides the random ones.
    #[arg(long)]
    pub candidate_file: Option<PathBuf>,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Without --data: the measurement noise per coordinate assumed (model length unit);
    /// default 1e-5 of the arm's reach.
    #[arg(long)]
    pub noise: Option<f64>,
    /// Without --data: the RMS position error assumed to remain after the geometric (DH)
    /// calibration, CbD's prior (model length unit); default 3e-4 of the arm's reach.
    #[arg(long)]
    pub prior_error: Option<f64>,
    /// Workspace points whose mean posterior variance each step reduces.
    #[arg(long, default_value_t = 96)]
    pub workspace: usize,
    /// What chooses the poses: `variance` (a D-optimal geometric stage, then the largest reduction
    /// of CbD's posterior variance over the workspace) or `maximin` (model-free space filling: the
    /// candidate farthest in joint angle from every pose measured or chosen; a hedge where the kernel
    /// misjudges the error — on the simulated RR arm 32 such poses match 61–97 random ones;
    /// BENCHMARKS "Planning poses").
    #[arg(long, default_value = "variance", value_parser = ["variance", "maximin"])]
    pub criterion: String,
    /// Exchange passes after the greedy choice: each planned pose in turn is replaced by the
    /// candidate that most lowers the workspace's mean posterior variance given the others (never
    /// the --data poses); stops early when a pass swaps nothing. 0: the greedy choice as is.
    #[arg(long, default_value_t = 0)]
    pub exchange: usize,
    /// Workspace points the exchange passes score on: 0, the greedy step's; else a fresh uniform
    /// sample of this size per pass.
    #[arg(long, default_value_t = 0)]
    pub exchange_workspace: usize,
    /// Write the plan as JSON: every pose with its stage and the predicted RMS error after it
    /// (the learning curve), the hyperparameters, counts and timing.
    #[arg(long)]
    pub json: Option<PathBuf>,
}

pub fn run(args: PlanArgs) -> Result<()> {
    if let Some(count) = args.check {
        return run_check(&args, count);
    }
    let count = args.count.expect("clap requires --count without --check");
    crate::io::check_paths(
        &[("--model", args.model.model.as_deref()), ("--data", args.data.as_deref()), ("--candidate-file", args.candidate_file.as_deref())],
        &[("--out", Some(&args.out)), ("--json", args.json.as_deref())],
    )?;
    if count == 0 {
        return Err(Error::InvalidInput("--count must be at least 1".into()));
    }
    if args.workspace == 0 {
        return Err(Error::InvalidInput("--workspace must be at least 1".into()));
    }
    for (flag, v) in [("--noise", args.noise), ("--prior-error", args.prior_error)] {
        if let Some(v) = v {
            if let Some(refusal) = crate::limits::positive_scale_out_of_bounds(flag, v) {
                return Err(Error::InvalidInput(refusal));
            }
        }
    }
    let arm = ArmModel::read(&args.model)?;
    let (mut nominal, spec) = (arm.nominal.clone(), &arm.spec);
    let model_name = arm.name();
    if nominal.tool_point_count() > 1 {
        return Err(crate::plan::PlanError::ToolPoints { points: nominal.tool_point_count() }).context(&model_name);
    }
    let limits = spec.joint_limits.clone();
    if let Some(d) = limits.iter().position(|[lo, hi]| !(lo.is_finite() && hi.is_finite())) {
        return Err(Error::InvalidInput(format!(
            "{model_name}: joint {} has no finite limits: declare `joint_limits` in its [measurements]",
            d + 1
        )));
    }
    let measured = match &args.data {
        Some(path) => Some(read_measurements(path, spec)?.measurements),
        None => None,
    };
    // The frame `cbd fit` fits in: a base declared unknown (`register = true`) registered on the
    // measured poses, as fit registers it, before the geometry and hyperparameters are chosen on
    // them (plan kept the declared identity base: the nominal chosen, 0.55 mm predicted where fit
    // reaches 0.038 mm).
    if let (Some(data), Some(path)) = (&measured, &args.data) {
        crate::cli::register_base_if_unknown(&arm, &mut nominal, data, path)?;
    }
    // The controller's values (the columns, in model units: where the limits apply) → the model's
    // joints, as the import maps them: the joint map, then a planar frame's offsets.
    let columns = crate::data::joint_columns::JointColumns::new(&spec);
    let joint_factor = columns.factors().to_vec();
    let to_model = |c: &[f64]| -> Vec<f64> { columns.to_model_from_model_units(c) };
    let mapped = spec.joint_map.is_some() || spec.planar_frame.as_ref().is_some_and(|f| f.offsets.iter().any(|o| *o != 0.0));
    let user_candidates = match &args.candidate_file {
        Some(path) => {
            // Read as the controller's values: units converted and limits checked, not mapped.
            let joints_only = ColumnSpec {
                position_columns: Vec::new(),
                min_rows: 1,
                joint_map: None,
                planar_frame: None,
                tool_points: Vec::new(),
                orientation_columns: None,
                ..spec.clone()
            };
            read_measurements(path, &joints_only)?.measurements.joints
        }
        None => Vec::new(),
    };
    let options = PlanOptions {
        count,
        candidates: args.candidates,
        seed: args.seed,
        workspace: args.workspace,
        exchange: args.exchange,
        exchange_workspace: args.exchange_workspace,
        criterion: match args.criterion.as_str() {
            "maximin" => Criterion::Maximin,
            _ => Criterion::Variance,
        },
        ..PlanOptions::default()
    };
    if options.criterion == Criterion::Maximin && options.exchange > 0 {
        return Err(Error::InvalidInput("--exchange improves the variance criterion: it does not combine with --criterion maximin".into()));
    }
    // More poses than candidates can never be planned: said before the memory estimate, which
    // would blame --candidates for what --count asks.
    let candidate_count = args.candidates + user_candidates.len() / nominal.n_joints().max(1);
    if count > candidate_count {
        return Err(Error::InvalidInput(format!(
            "--count {} is more than the {candidate_count} candidate poses (--candidates {} and --candidate-file): lower --count or raise --candidates",
            count, args.candidates
        )));
    }
    let bytes = crate::plan::memory_bytes(
        nominal.n_joints(),
        nominal.task_dim(),
        &options,
        user_candidates.len() / nominal.n_joints().max(1),
        measured.as_ref().map_or(0, |d| d.len()),
    );
    // The largest matrix side: the candidates' or a workspace's covariance rows, or the measured
    // and planned poses' (each of m coordinates).
    let measured_rows = measured.as_ref().map_or(0, |d| d.len());
    let dim = nominal.task_dim()
        * [candidate_count, args.workspace.max(args.exchange_workspace), measured_rows + count].into_iter().max().unwrap_or(1);
    // The flags that size the need: --exchange-workspace where it is the larger workspace.
    let (workspace_flag, workspace) = match args.exchange > 0 && args.exchange_workspace > args.workspace {
        true => ("--exchange-workspace", args.exchange_workspace),
        false => ("--workspace", args.workspace),
    };
    crate::cli::memory::room_for(bytes, dim)
        .map_err(|e| crate::cli::memory::MemoryError(format!("{}; lower --count, --candidates or {workspace_flag}", e.0)))
        .context(format!("--candidates {} {workspace_flag} {workspace} --count {}", args.candidates, count))?;
    let sample: Vec<f64> = crate::plan::candidates::uniform_within(&limits, 500, args.seed.wrapping_add(2))
        .chunks_exact(limits.len())
        .flat_map(to_model)
        .collect();
    let reach = crate::plan::candidates::reach(&nominal, &sample);
    // CbD's evidence on --data only when those poses identify the geometric group with coordinates
    // to spare; otherwise the DH fit interpolates them, σ comes out near zero and so would the
    // predictions. Say so, and what is needed. With evidence, the model `cbd fit` would write on
    // them (its geometry and hyperparameters); without, the calibrated geometry with a stated prior.
    let data_name = args.data.as_ref().map_or(String::new(), |p| p.display().to_string());
    let evidence_from_data = match &measured {
        Some(data) => match crate::plan::identifiability::measured_identify_group(&nominal, &sample, &data.joints) {
            Ok(()) => true,
            Err(why) => {
                errln!("{data_name}: {}", why.describe());
                false
            }
        },
        None => false,
    };
    let (hyperparameters, geometry) = match &measured {
        Some(data) if evidence_from_data => {
            let (h, choice) = prior::from_measurements(&nominal, data).context(&data_name)?;
            errln!("{}", choice.describe());
            (h, choice.chosen)
        }
        _ => (
            prior::stated(
                &nominal,
                &sample,
                reach,
                prior::StatedPrior { error: args.prior_error.unwrap_or(3e-4 * reach), noise: args.noise.unwrap_or(1e-5 * reach) },
            ),
            crate::calibrate::Geometry::Calibrated,
        ),
    };
    let input = PlanInput {
        nominal: &nominal,
        limits: &limits,
        to_model: if mapped { Some(&to_model) } else { None },
        user_candidates: &user_candidates,
        measured: measured.as_ref(),
        hyperparameters,
        geometry,
    };
    let result = plan(&input, &options).context(&model_name)?;
    // A prediction is a finite length or none (group not identified): never "NaN mm".
    let predictions = result.measured_predicted_rms.iter().chain(result.poses.iter().filter_map(|p| p.predicted_rms.as_ref()));
    if let Some(bad) = predictions.copied().find(|v| !(v.is_finite() && *v <= crate::limits::MAX_MAGNITUDE)) {
        return Err(Error::InvalidInput(format!(
            "{model_name}: the predicted RMS error is {}: the model's lengths (reach {}) or the stated prior are beyond what the posterior can represent; check the DH table, the joint limits and --noise / --prior-error",
            crate::error::number(bad),
            crate::error::number(reach)
        )));
    }

    // The poses as the controller's values, in the file's units.
    let mut text = spec.joint_columns.join(",");
    text.push('\n');
    for pose in &result.poses {
        let row: Vec<String> = pose.controller.iter().zip(&joint_factor).map(|(c, f)| format!("{:?}", c / f)).collect();
        text.push_str(&row.join(","));
        text.push('\n');
    }
    crate::cli::write_atomically(&args.out, text.as_bytes())?;

    let unit = spec.model_length_unit.name();
    // Poses chosen before the geometric group was identified (every criterion).
    let geometric = result.geometric_identified_after.unwrap_or(result.poses.len()).min(result.poses.len());
    let stages = match (geometry, geometric, result.measured_predicted_rms.is_some()) {
        (crate::calibrate::Geometry::Nominal, ..) => {
            "the nominal geometry kept (CbD's evidence on --data): no geometric group to identify".to_string()
        }
        (_, 0, true) => format!(
            "the geometric group ({} parameters identifiable at the nominal geometry) identified by the measured poses",
            result.geometric_parameters
        ),
        _ => format!(
            "{geometric} before the geometric group ({} parameters identifiable at the nominal geometry) is identified, {} after",
            result.geometric_parameters,
            result.poses.len() - geometric
        ),
    };
    errln!(
        "planned {} poses from {} candidates ({} within 1° of a singular configuration left out) in {:.2} s: {stages}",
        result.poses.len(),
        result.candidates,
        result.rejected_singular,
        result.seconds,
    );
    if options.exchange > 0 {
        errln!("exchange passes (at most {}): {} swaps", options.exchange, result.exchange_swaps);
    }
    if let Some(e) = result.measured_predicted_rms {
        errln!("predicted RMS position error after the measured poses: {e:.4e} {unit}");
    }
    let fmt = |v: Option<f64>| v.map_or("– (geometric group not yet identified)".to_string(), |e| format!("{e:.4e} {unit}"));
    for k in [9, 19, 29, 49, 99, 199] {
        if let Some(p) = result.poses.get(k).filter(|_| k + 1 < result.poses.len()) {
            errln!("  after {:>4} planned poses: predicted RMS error {}", k + 1, fmt(p.predicted_rms));
        }
    }
    if let Some(p) = result.poses.last() {
        errln!("  after {:>4} planned poses: predicted RMS error {}", result.poses.len(), fmt(p.predicted_rms));
    }
    errln!("wrote {} poses to {}", result.poses.len(), args.out.display());
    if let Some(path) = &args.json {
        let curve: Vec<serde_json::Value> = result
            .poses
            .iter()
            .enumerate()
            .map(|(k, p)| serde_json::json!({"poses": k + 1, "predicted_rms": p.predicted_rms, "stage": p.stage}))
            .collect();
        let json = serde_json::json!({
            "length_unit": unit,
            "learning_curve": curve,
            "plan": result,
            "criterion": options.criterion,
            "prior": if evidence_from_data { "evidence on --data" } else { "stated" },
        });
        let text = serde_json::to_string_pretty(&json).map_err(Error::JsonOutput)?;
        crate::cli::write_atomically(path, text.as_bytes())?;
    }
    Ok(())
}

/// `cbd plan --check N --blob B`: the check's poses and the smallest change of each kind it
/// detects (`plan::check`).
fn run_check(args: &PlanArgs, count: usize) -> Result<()> {
    let blob_path = args.blob.as_ref().expect("clap requires --blob with --check");
    crate::io::check_paths(
        &[("--model", args.model.model.as_deref()), ("--blob", Some(blob_path))],
        &[("--out", Some(&args.out)), ("--json", args.json.as_deref())],
    )?;
    if count == 0 {
        return Err(Error::InvalidInput("--check must be at least 1".into()));
    }
    if !(args.alpha > 0.0 && args.alpha < 1.0) {
        return Err(Error::InvalidInput(format!(
            "--alpha must be a number between 0 and 1 (exclusive), got {}",
            crate::error::number(args.alpha)
        )));
    }
    let arm = ArmModel::read(&args.model)?;
    let model_name = arm.name();
    let (nominal, spec) = (&arm.nominal, &arm.spec);
    let limits = spec.joint_limits.clone();
    if let Some(d) = limits.iter().position(|[lo, hi]| !(lo.is_finite() && hi.is_finite())) {
        return Err(Error::InvalidInput(format!(
            "{model_name}: joint {} has no finite limits: declare `joint_limits` in its [measurements]",
            d + 1
        )));
    }
    let blob = crate::data::read_capped(blob_path, crate::data::MAX_BLOB_BYTES, "blob")?;
    let model = crate::cli::blob_rows::decode_fitting(&blob, blob_path, &args.model, nominal, spec)?;
    if crate::cli::blob_rows::recorded_sigma(&model, blob_path)?.is_none() {
        return Err(Error::InvalidInput(format!("{}: {}", blob_path.display(), crate::evaluation::check::CheckError::NoSigma)));
    }
    let columns = crate::data::joint_columns::JointColumns::new(spec);
    let joint_factor = columns.factors().to_vec();
    let to_model = |c: &[f64]| -> Vec<f64> { columns.to_model_from_model_units(c) };
    let mapped = spec.joint_map.is_some() || spec.planar_frame.as_ref().is_some_and(|f| f.offsets.iter().any(|o| *o != 0.0));
    let unit = spec.model_length_unit.name();
    let input = crate::plan::check::CheckPlanInput {
        model: &model,
        geometry: model.nominal != *nominal,
        limits: &limits,
        to_model: if mapped { Some(&to_model) } else { None },
        count,
        candidates: args.candidates,
        seed: args.seed,
        alpha: args.alpha,
        register: args.register || arm.register_base(),
        unit,
    };
    let result = crate::plan::check::plan_check(&input).map_err(|e| Error::InvalidInput(format!("{}: {e}", blob_path.display())))?;
    let n = model.n_joints();
    let mut text = spec.joint_columns.join(",");
    text.push('\n');
    for pose in result.controller.chunks_exact(n) {
        let row: Vec<String> = pose.iter().zip(&joint_factor).map(|(c, f)| format!("{:?}", c / f)).collect();
        text.push_str(&row.join(","));
        text.push('\n');
    }
    crate::cli::write_atomically(&args.out, text.as_bytes())?;
    errln!(
        "planned {count} check poses from {} candidates ({} within 1° of a singular configuration left out) in {:.2} s",
        result.candidates,
        result.rejected_singular,
        result.seconds
    );
    outln!(
        "smallest change the check detects at alpha = {} with {:.0} % power ({} degrees of freedom, noncentrality {:.2}), {count} poses:",
        args.alpha,
        100.0 * result.power,
        result.dof,
        result.noncentrality
    );
    outln!("{:<26} {:>12} {:>12} {:>8}  unit", "change", "random", "planned", "ratio");
    for s in &result.sizes {
        outln!(
            "{:<26} {:>12.4e} {:>12.4e} {:>8.2}  {}",
            s.effect,
            s.random,
            s.planned,
            s.random / s.planned,
            if s.unit.is_empty() { "(ratio)" } else { &s.unit }
        );
    }
    if !result.framed.is_empty() {
        outln!("taken up by the registered frame (no size detects them): {}", result.framed.join(", "));
    }
    if !result.invisible.is_empty() {
        outln!("not seen at the measured point (no size detects them): {}", result.invisible.join(", "));
    }
    errln!("wrote {count} poses to {}", args.out.display());
    if let Some(path) = &args.json {
        let json = serde_json::json!({
            "length_unit": unit,
            "check_poses": count,
            "alpha": result.alpha,
            "power": result.power,
            "dof": result.dof,
            "noncentrality": result.noncentrality,
            "random_sets": crate::plan::check::RANDOM_SETS,
            "sizes": result.sizes,
            "not_seen": result.invisible,
            "taken_up_by_the_frame": result.framed,
            "candidates": result.candidates,
            "rejected_singular": result.rejected_singular,
            "poses": result.controller.chunks_exact(n).map(|p| p.to_vec()).collect::<Vec<_>>(),
        });
        let text = serde_json::to_string_pretty(&json).map_err(Error::JsonOutput)?;
        crate::cli::write_atomically(path, text.as_bytes())?;
    }
    Ok(())
}

//! `cbd plan`: where to measure next (`crate::face::plan`; `--check`: for `cbd check`) — poses within the joint limits, away from singular
//! configurations, chosen for the geometric group's identifiability and then for CbD's posterior
//! variance, with the RMS error the posterior predicts after each (docs/DESIGN.md §13).

use crate::cli::{ArmModel, ModelArgs};
use crate::error::{Error, Result};
use crate::face::{Dataset, PlanSettings};
use crate::plan::{Criterion, PlanOptions};
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
    let settings = PlanSettings { options, noise: args.noise, prior_error: args.prior_error };
    settings.validate()?;
    let arm = ArmModel::read(&args.model)?;
    crate::face::check_plannable(&arm)?;
    let measured = args.data.as_ref().map(|path| Dataset::read(path, &arm.spec)).transpose()?;
    let candidates = match &args.candidate_file {
        Some(path) => Dataset::read(path, &crate::face::candidates_spec(&arm.spec))?.imported.measurements.joints,
        None => Vec::new(),
    };
    let plan = crate::face::plan(&arm, measured.as_ref(), candidates, &settings)?;
    let poses = plan.poses_in_file_units();
    write_poses(&args.out, &arm.spec.joint_columns, poses.iter().map(Vec::as_slice))?;
    errln!("wrote {} poses to {}", poses.len(), args.out.display());
    if let Some(path) = &args.json {
        let text = serde_json::to_string_pretty(&plan.to_json()).map_err(Error::JsonOutput)?;
        crate::cli::write_atomically(path, text.as_bytes())?;
    }
    Ok(())
}

/// Writes `poses` (the controller's values in the file's units) as a CSV with the model file's joint `columns`.
fn write_poses<'p>(out: &std::path::Path, columns: &[String], poses: impl Iterator<Item = &'p [f64]>) -> Result<()> {
    let mut text = columns.join(",");
    text.push('\n');
    for pose in poses {
        let row: Vec<String> = pose.iter().map(|c| format!("{c:?}")).collect();
        text.push_str(&row.join(","));
        text.push('\n');
    }
    crate::cli::write_atomically(out, text.as_bytes())
}

/// `cbd plan --check N --blob B`: the check's poses and the smallest change of each kind it
/// detects (`crate::face::plan_check`).
fn run_check(args: &PlanArgs, count: usize) -> Result<()> {
    let blob_path = args.blob.as_ref().expect("clap requires --blob with --check");
    crate::io::check_paths(
        &[("--model", args.model.model.as_deref()), ("--blob", Some(blob_path))],
        &[("--out", Some(&args.out)), ("--json", args.json.as_deref())],
    )?;
    let settings =
        crate::face::CheckPlanSettings { count, candidates: args.candidates, seed: args.seed, alpha: args.alpha, register: args.register };
    settings.validate()?;
    let arm = ArmModel::read(&args.model)?;
    let blob = crate::face::read_blob(blob_path)?;
    let model = crate::cli::blob_rows::decode_fitting(&blob, blob_path, &args.model, &arm.nominal, &arm.spec)?;
    let plan = crate::face::plan_check(&arm, crate::face::DecodedBlob { model, source: blob_path }, &settings)?;
    let poses = plan.poses_in_file_units();
    write_poses(&args.out, &arm.spec.joint_columns, poses.iter().map(Vec::as_slice))?;
    for line in plan.table() {
        outln!("{line}");
    }
    errln!("wrote {count} poses to {}", args.out.display());
    if let Some(path) = &args.json {
        let text = serde_json::to_string_pretty(&plan.to_json()).map_err(Error::JsonOutput)?;
        crate::cli::write_atomically(path, text.as_bytes())?;
    }
    Ok(())
}

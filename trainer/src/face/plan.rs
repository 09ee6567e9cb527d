//! Where to measure next (`cbd plan`): poses within the joint limits, away from singular
//! configurations, chosen for the geometric group's identifiability and then for CbD's posterior
//! variance, with the RMS error the posterior predicts after each (docs/DESIGN.md §13).

use super::{ArmModel, Dataset};
use crate::data::csv_import::ColumnSpec;
use crate::error::{Context, Error, Result};
use crate::plan::{prior, Criterion, PlanInput, PlanOptions};

/// What a plan is asked: the poses' count and how they are chosen, and without measured poses the
/// prior it assumes (`cbd plan`'s flags but its files).
#[derive(Debug, Clone)]
pub struct PlanSettings {
    pub options: PlanOptions,
    /// Without measured poses: the measurement noise per coordinate assumed (model length unit);
    /// `None`: 1e-5 of the arm's reach.
    pub noise: Option<f64>,
    /// Without measured poses: the RMS position error assumed to remain after the geometric (DH)
    /// calibration, CbD's prior (model length unit); `None`: 3e-4 of the arm's reach.
    pub prior_error: Option<f64>,
}

impl PlanSettings {
    /// Rejects out-of-range values before any work, naming the flag.
    pub fn validate(&self) -> Result<()> {
        if self.options.count == 0 {
            return Err(Error::InvalidInput("--count must be at least 1".into()));
        }
        if self.options.workspace == 0 {
            return Err(Error::InvalidInput("--workspace must be at least 1".into()));
        }
        for (flag, v) in [("--noise", self.noise), ("--prior-error", self.prior_error)] {
            if let Some(v) = v {
                if let Some(refusal) = crate::limits::positive_scale_out_of_bounds(flag, v) {
                    return Err(Error::InvalidInput(refusal));
                }
            }
        }
        Ok(())
    }
}

/// Whether `arm` can be planned for: one tool point, finite joint limits (before a front reads
/// any poses, so that the arm's fault is named first).
pub fn check_plannable(arm: &ArmModel) -> Result<()> {
    if arm.nominal.tool_point_count() > 1 {
        return Err(crate::plan::PlanError::ToolPoints { points: arm.nominal.tool_point_count() }).context(arm.name());
    }
    check_finite_limits(arm)
}

/// Poses are drawn within the joint limits: every joint needs finite ones.
pub(super) fn check_finite_limits(arm: &ArmModel) -> Result<()> {
    if let Some(d) = arm.spec.joint_limits.iter().position(|[lo, hi]| !(lo.is_finite() && hi.is_finite())) {
        return Err(Error::InvalidInput(format!(
            "{}: joint {} has no finite limits: declare `joint_limits` in its [measurements]",
            arm.name(),
            d + 1
        )));
    }
    Ok(())
}

/// Whether the import maps the controller's values to other model joints (a joint map, a planar
/// frame's offsets): then a plan's candidates, drawn as the controller's values, are mapped.
pub(super) fn maps_joints(spec: &ColumnSpec) -> bool {
    spec.joint_map.is_some() || spec.planar_frame.as_ref().is_some_and(|f| f.offsets.iter().any(|o| *o != 0.0))
}

/// The columns a file of candidate poses is read with: `spec`'s joint columns, read as the
/// controller's values (units converted and limits checked, not mapped).
pub fn candidates_spec(spec: &ColumnSpec) -> ColumnSpec {
    ColumnSpec {
        position_columns: Vec::new(),
        min_rows: 1,
        joint_map: None,
        planar_frame: None,
        tool_points: Vec::new(),
        orientation_columns: None,
        ..spec.clone()
    }
}

/// A plan: the poses chosen with the predicted error after each, and what chose them.
pub struct Plan {
    pub plan: crate::plan::Plan,
    options: PlanOptions,
    /// The prior came from CbD's evidence on the measured poses (else it was stated).
    evidence_from_data: bool,
    /// Each joint column's factor from the file's units to the model's.
    joint_factor: Vec<f64>,
    unit: &'static str,
}

impl Plan {
    /// The planned poses as the controller's values, in the model file's joint units (its columns'
    /// order: `ArmModel::spec.joint_columns`).
    pub fn poses_in_file_units(&self) -> Vec<Vec<f64>> {
        self.plan.poses.iter().map(|pose| pose.controller.iter().zip(&self.joint_factor).map(|(c, f)| c / f).collect()).collect()
    }

    /// `cbd plan --json`'s value: every pose with its stage and the predicted RMS error after it
    /// (the learning curve), the hyperparameters, counts and timing.
    pub fn to_json(&self) -> serde_json::Value {
        let result = &self.plan;
        let curve: Vec<serde_json::Value> = result
            .poses
            .iter()
            .enumerate()
            .map(|(k, p)| serde_json::json!({"poses": k + 1, "predicted_rms": p.predicted_rms, "stage": p.stage}))
            .collect();
        serde_json::json!({
            "length_unit": self.unit,
            "learning_curve": curve,
            "plan": result,
            "criterion": self.options.criterion,
            "prior": if self.evidence_from_data { "evidence on --data" } else { "stated" },
        })
    }
}

/// Plans `settings.options.count` poses for `arm`, continuing from the `measured` poses (their
/// base registered as `cbd fit` registers it; the hyperparameters from CbD's evidence on them),
/// among random candidates and the `candidates` given (controller values in model units,
/// row-major: read with [`candidates_spec`]). What it chose is said on the message channel.
pub fn plan(arm: &ArmModel, measured: Option<&Dataset>, candidates: Vec<f64>, settings: &PlanSettings) -> Result<Plan> {
    settings.validate()?;
    check_plannable(arm)?;
    let (mut nominal, spec) = (arm.nominal.clone(), &arm.spec);
    let model_name = arm.name();
    let limits = spec.joint_limits.clone();
    let user_candidates = candidates;
    let data_name = measured.map_or(String::new(), |d| d.source.display().to_string());
    let measured_path = measured.map(|d| d.source.clone());
    let measured = measured.map(|d| d.imported.measurements.clone());
    // The frame `cbd fit` fits in: a base declared unknown (`register = true`) registered on the
    // measured poses, as fit registers it, before the geometry and hyperparameters are chosen on
    // them (plan kept the declared identity base: the nominal chosen, 0.55 mm predicted where fit
    // reaches 0.038 mm).
    if let (Some(data), Some(path)) = (&measured, &measured_path) {
        super::register_base_if_unknown(arm, &mut nominal, data, path)?;
    }
    // The controller's values (the columns, in model units: where the limits apply) → the model's
    // joints, as the import maps them: the joint map, then a planar frame's offsets.
    let columns = crate::data::joint_columns::JointColumns::new(spec);
    let joint_factor = columns.factors().to_vec();
    let to_model = |c: &[f64]| -> Vec<f64> { columns.to_model_from_model_units(c) };
    let mapped = maps_joints(spec);
    let options = settings.options.clone();
    let count = options.count;
    if options.criterion == Criterion::Maximin && options.exchange > 0 {
        return Err(Error::InvalidInput("--exchange improves the variance criterion: it does not combine with --criterion maximin".into()));
    }
    // More poses than candidates can never be planned: said before the memory estimate, which
    // would blame --candidates for what --count asks.
    let candidate_count = options.candidates + user_candidates.len() / nominal.n_joints().max(1);
    if count > candidate_count {
        return Err(Error::InvalidInput(format!(
            "--count {} is more than the {candidate_count} candidate poses (--candidates {} and --candidate-file): lower --count or raise --candidates",
            options.count, options.candidates
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
        * [candidate_count, options.workspace.max(options.exchange_workspace), measured_rows + count].into_iter().max().unwrap_or(1);
    // The flags that size the need: --exchange-workspace where it is the larger workspace.
    let (workspace_flag, workspace) = match options.exchange > 0 && options.exchange_workspace > options.workspace {
        true => ("--exchange-workspace", options.exchange_workspace),
        false => ("--workspace", options.workspace),
    };
    crate::memory::room_for(bytes, dim)
        .map_err(|e| crate::memory::MemoryError(format!("{}; lower --count, --candidates or {workspace_flag}", e.0)))
        .context(format!("--candidates {} {workspace_flag} {workspace} --count {}", options.candidates, count))?;
    let sample: Vec<f64> = crate::plan::candidates::uniform_within(&limits, 500, options.seed.wrapping_add(2))
        .chunks_exact(limits.len())
        .flat_map(to_model)
        .collect();
    let reach = crate::plan::candidates::reach(&nominal, &sample);
    // CbD's evidence on --data only when those poses identify the geometric group with coordinates
    // to spare; otherwise the DH fit interpolates them, σ comes out near zero and so would the
    // predictions. Say so, and what is needed. With evidence, the model `cbd fit` would write on
    // them (its geometry and hyperparameters); without, the calibrated geometry with a stated prior.
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
                prior::StatedPrior { error: settings.prior_error.unwrap_or(3e-4 * reach), noise: settings.noise.unwrap_or(1e-5 * reach) },
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
    let result = crate::plan::plan(&input, &options).context(&model_name)?;
    // A prediction is a finite length or none (group not identified): never "NaN mm".
    let predictions = result.measured_predicted_rms.iter().chain(result.poses.iter().filter_map(|p| p.predicted_rms.as_ref()));
    if let Some(bad) = predictions.copied().find(|v| !(v.is_finite() && *v <= crate::limits::MAX_MAGNITUDE)) {
        return Err(Error::InvalidInput(format!(
            "{model_name}: the predicted RMS error is {}: the model's lengths (reach {}) or the stated prior are beyond what the posterior can represent; check the DH table, the joint limits and --noise / --prior-error",
            crate::error::number(bad),
            crate::error::number(reach)
        )));
    }

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
    Ok(Plan { plan: result, options, evidence_from_data, joint_factor, unit })
}

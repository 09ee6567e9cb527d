//! Where to measure next (issue 28): a greedy choice of poses within the joint limits and away from
//! singular configurations — first D-optimal for the geometric group while it is not identified, then
//! the largest reduction of CbD's posterior variance over the workspace — and the RMS position error
//! the posterior predicts after calibrating on every prefix (docs/DESIGN.md §13).
//!
//! In pipeline order: `candidates` (sampling, limits, singular distance), `prior` (hyperparameters),
//! `identifiability` (the DH Jacobian's information), `posterior` (the Gaussian process), here the
//! greedy loop.

pub mod candidates;
pub mod identifiability;
pub mod posterior;
pub mod prior;

use crate::data::Measurements;
use crate::evidence::CbdHyperparameters;
use cbd_protocol::NominalModel;
use identifiability::Identifiability;
use posterior::{Posterior, Prior};

/// Sizes of the sets the planner works on.
#[derive(Debug, Clone, PartialEq)]
pub struct PlanOptions {
    /// Poses to choose.
    pub count: usize,
    /// Random candidates within the limits (besides the user's).
    pub candidates: usize,
    pub seed: u64,
    /// Workspace points whose mean posterior variance the greedy step reduces.
    pub workspace: usize,
    /// Independent workspace points the predicted error is averaged over.
    pub evaluation: usize,
    /// Measured poses the posterior is conditioned on (evenly spaced when there are more); the
    /// geometric group's information uses all of them.
    pub max_conditioning: usize,
}

impl Default for PlanOptions {
    fn default() -> Self {
        PlanOptions { count: 20, candidates: 10_000, seed: 1, workspace: 96, evaluation: 500, max_conditioning: 100 }
    }
}

/// What the planner is given.
pub struct PlanInput<'a> {
    pub nominal: &'a NominalModel,
    /// `[lo, hi]` per joint, model units; finite.
    pub limits: &'a [[f64; 2]],
    /// The user's own candidates (row-major), already checked against the limits.
    pub user_candidates: &'a [f64],
    /// Poses already measured.
    pub measured: Option<&'a Measurements>,
    pub hyperparameters: CbdHyperparameters,
}

/// Which criterion chose a pose.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Stage {
    /// D-optimality of the geometric group's Jacobian.
    Geometric,
    /// Reduction of CbD's posterior variance over the workspace.
    Posterior,
}

/// One planned pose.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct PlannedPose {
    /// Model units (radians, or the length unit for prismatic joints).
    pub joints: Vec<f64>,
    pub stage: Stage,
    /// Linearised distance to the nearest singular configuration, radians.
    pub singular_distance: f64,
    /// Predicted RMS position error on the workspace after calibrating (dh+cbd) on the measured
    /// poses and the planned ones up to this one; `None` while the geometric group is rank deficient.
    pub predicted_rms: Option<f64>,
    /// Its non-parametric part alone (CbD's posterior).
    pub predicted_rms_cbd: f64,
}

/// The plan.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Plan {
    pub poses: Vec<PlannedPose>,
    /// Predicted RMS error after the measured poses alone (with `--data`).
    pub measured_predicted_rms: Option<f64>,
    /// The prior's RMS error of the non-parametric part (no pose measured).
    pub prior_rms_cbd: f64,
    pub candidates: usize,
    /// Candidates left out: within 1° of a singular configuration.
    pub rejected_singular: usize,
    /// Identifiable geometric parameters (DH, base, tool) and the pose after which they are.
    pub geometric_parameters: usize,
    pub geometric_identified_after: Option<usize>,
    pub reach: f64,
    pub hyperparameters: CbdHyperparameters,
    pub seconds: f64,
}

/// Why no plan.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PlanError {
    #[error("joint {joint} has no finite limits: declare `joint_limits` in the model file's [measurements]")]
    UnboundedJoint { joint: usize },
    #[error("{count} poses asked for, but only {available} candidates are at least 1° from a singular configuration; raise --candidates")]
    TooFewCandidates { count: usize, available: usize },
    #[error("the model has {model} joints; {what} has {given}")]
    Shape { model: usize, given: usize, what: &'static str },
}

impl From<PlanError> for crate::Error {
    fn from(e: PlanError) -> crate::Error {
        crate::Error::stage("plan", e)
    }
}

/// Plans `options.count` poses (see the module documentation).
pub fn plan(input: &PlanInput, options: &PlanOptions) -> Result<Plan, PlanError> {
    let start = std::time::Instant::now();
    let nominal = input.nominal;
    let (n, m) = (nominal.n_joints(), nominal.task_dim());
    if input.limits.len() != n {
        return Err(PlanError::Shape { model: n, given: input.limits.len(), what: "the joint limits" });
    }
    if let Some(d) = input.limits.iter().position(|[lo, hi]| !(lo.is_finite() && hi.is_finite())) {
        return Err(PlanError::UnboundedJoint { joint: d + 1 });
    }
    if let Some(data) = input.measured.filter(|d| d.n_joints != n || d.task_dim != m) {
        return Err(PlanError::Shape { model: n, given: data.n_joints, what: "the measured data" });
    }
    let workspace = candidates::uniform_within(input.limits, options.workspace, options.seed.wrapping_add(1));
    let evaluation = candidates::uniform_within(input.limits, options.evaluation, options.seed.wrapping_add(2));
    let reach = candidates::reach(nominal, &evaluation);

    // Candidates: the user's and random ones, each at least 1° from a singular configuration.
    let mut pool: Vec<f64> = input.user_candidates.to_vec();
    pool.extend(candidates::uniform_within(input.limits, options.candidates, options.seed));
    let (mut kept, mut distances, mut rejected_singular) = (Vec::new(), Vec::new(), 0);
    for q in pool.chunks_exact(n) {
        let d = candidates::singular_distance(nominal, q, reach);
        if d >= candidates::SINGULAR_MARGIN && candidates::within_limits(q, input.limits) {
            kept.extend_from_slice(q);
            distances.push(d);
        } else {
            rejected_singular += 1;
        }
    }
    let count_c = distances.len();
    if count_c < options.count {
        return Err(PlanError::TooFewCandidates { count: options.count, available: count_c });
    }

    // The geometric group on [candidates | measured | evaluation].
    let measured_joints: &[f64] = input.measured.map(|d| d.joints.as_slice()).unwrap_or(&[]);
    let count_d = measured_joints.len() / n;
    let mut all = kept.clone();
    all.extend_from_slice(measured_joints);
    all.extend_from_slice(&evaluation);
    let mut geometric = crate::parametric::identification_jacobian(nominal, &all)
        .map(|(jac, identifiable)| Identifiability::new(&jac, m, count_c, count_c + count_d, &identifiable));

    // The posterior on [candidates | workspace | evaluation | measured (at most max_conditioning)].
    let prior = Prior::new(&input.hyperparameters, m);
    let conditioned = crate::data::evenly_spaced_rows(count_d, options.max_conditioning);
    let mut points: Vec<_> = kept.chunks_exact(n).map(|q| prior.point(nominal, q)).collect();
    points.extend(workspace.chunks_exact(n).map(|q| prior.point(nominal, q)));
    points.extend(evaluation.chunks_exact(n).map(|q| prior.point(nominal, q)));
    points.extend(conditioned.iter().map(|&i| prior.point(nominal, &measured_joints[i * n..(i + 1) * n])));
    let eval_range = count_c + options.workspace..count_c + options.workspace + options.evaluation;
    let measured_start = eval_range.end;
    let mut gp = Posterior::new(prior, points, count_c, options.workspace);
    let prior_rms_cbd = gp.mean_variance(eval_range.clone()).sqrt();

    if let Some(g) = geometric.as_mut() {
        for i in 0..count_d {
            g.add(count_c + i);
        }
    }
    for k in 0..conditioned.len() {
        gp.add(measured_start + k);
    }
    let sigma2 = gp.sigma2();
    let predict = |gp: &Posterior, g: &Option<Identifiability>| -> (Option<f64>, f64) {
        let cbd = gp.mean_variance(eval_range.clone());
        let parametric = match g {
            Some(g) => g.predicted_variance(sigma2),
            None => Some(0.0),
        };
        (parametric.map(|p| (p + cbd).sqrt()), cbd.sqrt())
    };
    let measured_predicted_rms = if count_d > 0 { predict(&gp, &geometric).0 } else { None };

    let mut chosen = vec![false; count_c];
    let mut poses = Vec::with_capacity(options.count);
    let mut geometric_identified_after = None;
    for step in 0..options.count {
        // Identified: full rank, and its parametric error no larger than the non-parametric one.
        let identified = match &geometric {
            None => true,
            Some(g) => match g.predicted_variance(sigma2) {
                Some(p) => p <= gp.mean_variance(eval_range.clone()),
                None => false,
            },
        };
        if identified && geometric_identified_after.is_none() {
            geometric_identified_after = Some(step);
        }
        let stage = if identified { Stage::Posterior } else { Stage::Geometric };
        let score = |c: usize| match (stage, &geometric) {
            (Stage::Geometric, Some(g)) => g.gain(c),
            _ => gp.gain(c),
        };
        let best = (0..count_c).filter(|&c| !chosen[c]).map(|c| (c, score(c))).max_by(|a, b| a.1.total_cmp(&b.1));
        let Some((c, _)) = best else { break };
        chosen[c] = true;
        if let Some(g) = geometric.as_mut() {
            g.add(c);
        }
        gp.add(c);
        let (predicted_rms, predicted_rms_cbd) = predict(&gp, &geometric);
        poses.push(PlannedPose {
            joints: kept[c * n..(c + 1) * n].to_vec(),
            stage,
            singular_distance: distances[c],
            predicted_rms,
            predicted_rms_cbd,
        });
    }
    if geometric_identified_after.is_none() && geometric.as_ref().is_some_and(|g| g.predicted_variance(sigma2).is_some()) {
        geometric_identified_after = Some(poses.len());
    }
    Ok(Plan {
        poses,
        measured_predicted_rms,
        prior_rms_cbd,
        candidates: count_c,
        rejected_singular,
        geometric_parameters: geometric.as_ref().map_or(0, |g| g.parameters()),
        geometric_identified_after,
        reach,
        hyperparameters: input.hyperparameters.clone(),
        seconds: start.elapsed().as_secs_f64(),
    })
}

#[cfg(test)]
mod tests;

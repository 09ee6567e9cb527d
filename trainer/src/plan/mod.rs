//! Where to measure next (issue 28): a greedy choice of poses within the joint limits and away from
//! singular configurations, each the largest reduction of the mean posterior variance over the
//! workspace of dh+cbd's linearised model (CbD's Gaussian process plus the geometric group's
//! Jacobian as basis functions), and the RMS position error that posterior predicts after
//! calibrating on every prefix (docs/DESIGN.md §13).
//!
//! In pipeline order: `candidates` (sampling, limits, singular distance), `prior` (hyperparameters),
//! `identifiability` (the DH Jacobian and its information), `posterior` (the Gaussian process),
//! here the greedy loop, then `exchange` (optional passes that revise the greedy batch).

pub mod candidates;
pub mod check;
pub mod exchange;
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
    /// The first poses chosen by the largest posterior variance at the candidate itself (a
    /// space-filling start in the kernel's metric) instead of the workspace variance reduction.
    pub space_filling: usize,
    /// Every this-many-th pose (0: none) the next random candidate in sampling order, a uniform
    /// random pose, instead of the criterion's choice: a hedge against a kernel that misses part
    /// of the error (the uniform test distribution gets its share of poses whatever the process
    /// believes).
    pub random_every: usize,
    /// What chooses the poses: the variance criterion (after its geometric stage) or maximin.
    pub criterion: Criterion,
    /// Exchange passes after the greedy batch (0: none; passes stop early when one swaps nothing).
    pub exchange: usize,
    /// Workspace points the exchange passes score on: 0, the greedy step's; else an independent
    /// uniform sample of this size, fresh for every pass.
    pub exchange_workspace: usize,
}

impl Default for PlanOptions {
    fn default() -> Self {
        PlanOptions {
            count: 20,
            candidates: 10_000,
            seed: 1,
            workspace: 96,
            evaluation: 500,
            max_conditioning: 100,
            space_filling: 0,
            random_every: 0,
            criterion: Criterion::Variance,
            exchange: 0,
            exchange_workspace: 0,
        }
    }
}

/// What the planner is given.
pub struct PlanInput<'a> {
    pub nominal: &'a NominalModel,
    /// `[lo, hi]` per joint of the controller's values (model units); finite.
    pub limits: &'a [[f64; 2]],
    /// The controller's values → the model's joints (a model file's joint map, a planar frame's
    /// offsets); `None`: the identity. Candidates, workspace and evaluation points are uniform in
    /// the controller's values, as the limits are.
    pub to_model: Option<&'a dyn Fn(&[f64]) -> Vec<f64>>,
    /// The user's own candidates (row-major, controller values), already checked against the limits.
    pub user_candidates: &'a [f64],
    /// Poses already measured (model joints, as imported).
    pub measured: Option<&'a Measurements>,
    pub hyperparameters: CbdHyperparameters,
    /// The model planned for: CbD on the nominal chain, or with its geometric group calibrated
    /// (whose identifiability the plan then tracks) — what `cbd fit` chooses on the measured poses.
    pub geometry: crate::calibrate::Geometry,
}

/// What chooses the poses.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Criterion {
    /// The largest reduction of the mean posterior variance over the workspace (model-based).
    #[default]
    Variance,
    /// Model-free space filling: the candidate farthest in joint angle from every pose measured or
    /// chosen (greedy maximin; around the circle for a joint whose limits span a full turn), from
    /// the first pose on (a D-optimal geometric stage first made it worse on both simulated arms,
    /// BENCHMARKS "Planning poses"). It hedges against a kernel that misjudges where the error
    /// lies; the predicted error is still the posterior's.
    Maximin,
}

/// Which criterion chose a pose.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Stage {
    /// Reduction of the posterior variance over the workspace while the geometric group is not yet
    /// identified (its information rank deficient).
    Geometric,
    /// Reduction of the posterior variance over the workspace, the geometric group identified.
    Posterior,
    /// [`Criterion::Maximin`].
    Maximin,
}

/// One planned pose.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct PlannedPose {
    /// Model units (radians, or the length unit for prismatic joints).
    pub joints: Vec<f64>,
    pub stage: Stage,
    /// The controller's joint values (model units; where the limits apply): `joints` unless a
    /// joint map ([`PlanInput::to_model`]) is given.
    pub controller: Vec<f64>,
    /// Linearised distance to the nearest singular configuration, radians.
    pub singular_distance: f64,
    /// Predicted RMS position error on the workspace after calibrating (dh+cbd) on the measured
    /// poses and the planned ones up to this one; `None` while the geometric group is rank deficient.
    pub predicted_rms: Option<f64>,
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
    /// Swaps the exchange passes made (0 without them).
    pub exchange_swaps: usize,
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
    /// The Gaussian process tracks one position per pose; with several tool points a pose measures
    /// each, and their fields are correlated in a way the planner does not model.
    #[error("the model has {points} tool points ([chain] tool.points): cbd plan plans for one measured point per pose; plan with a model of one tool point (the points' centre) and measure every point at the planned poses")]
    ToolPoints { points: usize },
    #[error("the model has {model} joints; {what} has {given}")]
    Shape { model: usize, given: usize, what: &'static str },
}

impl From<PlanError> for crate::Error {
    fn from(e: PlanError) -> crate::Error {
        crate::Error::stage("plan", e)
    }
}

/// The parameters' prior standard deviation in units of the noise: broad enough that the prediction
/// is the least-squares fit's wherever the poses identify the group (posterior variance σ²/λ for
/// information λ ≫ 1e-6), and not so broad that the rank-m updates lose the noise-level variances
/// to cancellation (prior/posterior variance ≈ 1e8–1e10, 1e-6–1e-8 of f64's 16 digits).
const GEOMETRIC_PRIOR: f64 = 1e3;

/// Bytes [`plan`] holds for a chain of `n` joints and task dimension `m`, `user` candidates of the
/// user's and `measured` poses: per tracked point (candidates, workspace, evaluation, conditioned
/// poses) its kinematics, features, geometric rows (at most 6n + 6 parameters) and posterior rows
/// (m per added pose), and the candidate × workspace cross-covariances, m² each (the larger of the
/// greedy and the exchange workspace: one process is held at a time).
pub fn memory_bytes(n: usize, m: usize, options: &PlanOptions, user: usize, measured: usize) -> f64 {
    // An exchange pass appends at most two row groups per planned pose (a swap's downdate and
    // update) to a process of the same size, built afresh per pass.
    let exchange = options.exchange.min(1) * options.count;
    let added = (options.count + measured.min(options.max_conditioning) + 2 * exchange) as f64;
    let (n, m) = (n as f64, m as f64);
    let candidates = (options.candidates + user) as f64;
    let workspace = options.workspace.max(options.exchange_workspace) as f64;
    let points = candidates + workspace + (options.evaluation + measured) as f64;
    let per_point = 3.0 + n * m + 2.0 * n + 2.0 * m * (6.0 * n + 6.0) + (added + 2.0) * m * m + 2.0 * n;
    8.0 * (points * per_point + candidates * (workspace + 1.0) * m * m)
}

/// Plans `options.count` poses (see the module documentation).
pub fn plan(input: &PlanInput, options: &PlanOptions) -> Result<Plan, PlanError> {
    let start = std::time::Instant::now();
    let nominal = input.nominal;
    let (n, m) = (nominal.n_joints(), nominal.task_dim());
    let points = input.measured.map_or(1, |d| d.points_per_pose).max(nominal.tool_point_count());
    if points > 1 {
        return Err(PlanError::ToolPoints { points });
    }
    if input.limits.len() != n {
        return Err(PlanError::Shape { model: n, given: input.limits.len(), what: "the joint limits" });
    }
    if let Some(d) = input.limits.iter().position(|[lo, hi]| !(lo.is_finite() && hi.is_finite())) {
        return Err(PlanError::UnboundedJoint { joint: d + 1 });
    }
    if let Some(data) = input.measured.filter(|d| d.n_joints != n || d.task_dim != m) {
        return Err(PlanError::Shape { model: n, given: data.n_joints, what: "the measured data" });
    }
    if input.user_candidates.len() % n != 0 {
        return Err(PlanError::Shape { model: n, given: input.user_candidates.len() % n, what: "the last candidate" });
    }
    // Controller values (where the limits apply) and the model's joints.
    let to_model = |c: &[f64]| -> Vec<f64> {
        match input.to_model {
            Some(f) => c.chunks_exact(n).flat_map(f).collect(),
            None => c.to_vec(),
        }
    };
    let workspace = to_model(&candidates::uniform_within(input.limits, options.workspace, options.seed.wrapping_add(1)));
    let evaluation = to_model(&candidates::uniform_within(input.limits, options.evaluation, options.seed.wrapping_add(2)));
    let reach = candidates::reach(nominal, &evaluation);

    // Candidates: the user's and random ones, each at least 1° from a singular configuration.
    let mut pool: Vec<f64> = input.user_candidates.to_vec();
    pool.extend(candidates::uniform_within(input.limits, options.candidates, options.seed));
    let pool_model = to_model(&pool);
    let (mut kept, mut kept_controller, mut distances, mut rejected_singular) = (Vec::new(), Vec::new(), Vec::new(), 0);
    let mut user_count = 0;
    for (i, (c, q)) in pool.chunks_exact(n).zip(pool_model.chunks_exact(n)).enumerate() {
        let d = candidates::singular_distance(nominal, q, reach);
        if d >= candidates::SINGULAR_MARGIN && candidates::within_limits(c, input.limits) {
            kept.extend_from_slice(q);
            kept_controller.extend_from_slice(c);
            user_count += usize::from(i * n < input.user_candidates.len());
            distances.push(d);
        } else {
            rejected_singular += 1;
        }
    }
    let count_c = distances.len();
    if count_c < options.count {
        return Err(PlanError::TooFewCandidates { count: options.count, available: count_c });
    }

    // Every tracked point: [candidates | workspace | evaluation | measured].
    let measured_joints: &[f64] = input.measured.map(|d| d.joints.as_slice()).unwrap_or(&[]);
    let count_d = measured_joints.len() / n;
    let (count_w, count_e) = (options.workspace, options.evaluation);
    let eval_range = count_c + count_w..count_c + count_w + count_e;
    let measured_start = eval_range.end;
    let mut all = kept.clone();
    all.extend_from_slice(&workspace);
    all.extend_from_slice(&evaluation);
    all.extend_from_slice(measured_joints);
    let mut geometric = match input.geometry {
        crate::calibrate::Geometry::Nominal => None,
        _ => crate::parametric::identification_jacobian(nominal, &all)
            .map(|(jac, identifiable)| Identifiability::new(&jac, m, count_c, &identifiable)),
    };

    // The Gaussian process, conditioned on at most `max_conditioning` measured poses (evenly
    // spaced); the rest inform the geometric group's prior.
    let prior = Prior::new(&input.hyperparameters, m);
    let sigma2 = prior.sigma2.max(f64::MIN_POSITIVE);
    let conditioned = crate::data::evenly_spaced_rows(count_d, options.max_conditioning);
    let unconditioned: Vec<usize> = (0..count_d).filter(|i| conditioned.binary_search(i).is_err()).map(|i| measured_start + i).collect();
    let (p, factor) = match &geometric {
        Some(g) => (g.parameters(), g.prior_factor(GEOMETRIC_PRIOR * GEOMETRIC_PRIOR * sigma2, sigma2, &unconditioned)),
        None => (0, Vec::new()),
    };
    // The basis reads the rows only; `geometric` gains the chosen poses' information below.
    let rows = geometric.clone();
    let basis = |i: usize| -> Vec<f64> {
        let Some(g) = &rows else { return Vec::new() };
        times_factor(g.block(i), &factor, m, p)
    };
    let mut points: Vec<_> = (0..count_c + count_w + count_e).map(|i| prior.point(nominal, &all[i * n..(i + 1) * n], basis(i))).collect();
    points.extend(conditioned.iter().map(|&i| prior.point(nominal, &measured_joints[i * n..(i + 1) * n], basis(measured_start + i))));
    let prior_rms_cbd = (eval_range.clone().map(|i| prior.cbd_variance(&points[i])).sum::<f64>() / count_e.max(1) as f64).sqrt();
    let mut gp = Posterior::new(prior, points, count_c, count_w);

    if let Some(g) = geometric.as_mut() {
        for i in 0..count_d {
            g.add(measured_start + i);
        }
    }
    for k in 0..conditioned.len() {
        gp.add(measured_start + k);
    }
    let identified = |g: &Option<Identifiability>| g.as_ref().is_none_or(|g| g.full_rank());
    let predict = |gp: &Posterior, g: &Option<Identifiability>| identified(g).then(|| gp.mean_variance(eval_range.clone()).sqrt());
    let measured_predicted_rms = if count_d > 0 { predict(&gp, &geometric) } else { None };

    let mut chosen = vec![false; count_c];
    let mut batch = Vec::with_capacity(options.count);
    let mut poses = Vec::with_capacity(options.count);
    let geometric_measured = geometric.clone();
    let mut geometric_identified_after = identified(&geometric).then_some(0);
    let pose = |c: usize, stage: Stage, predicted_rms: Option<f64>| PlannedPose {
        joints: kept[c * n..(c + 1) * n].to_vec(),
        controller: kept_controller[c * n..(c + 1) * n].to_vec(),
        stage,
        singular_distance: distances[c],
        predicted_rms,
    };
    // Maximin: each candidate's squared joint-angle distance to the nearest pose measured or chosen.
    let full_turn: Vec<bool> = input.limits.iter().map(|[lo, hi]| hi - lo >= std::f64::consts::TAU - 1e-9).collect();
    let mut nearest: Vec<f64> = match options.criterion {
        Criterion::Variance => Vec::new(),
        Criterion::Maximin => (0..count_c)
            .map(|c| {
                let q = &kept[c * n..(c + 1) * n];
                measured_joints.chunks_exact(n).map(|h| joint_distance2(q, h, &full_turn)).fold(f64::INFINITY, f64::min)
            })
            .collect(),
    };
    for _ in 0..options.count {
        let stage = match (options.criterion, identified(&geometric)) {
            (Criterion::Maximin, _) => Stage::Maximin,
            (Criterion::Variance, true) => Stage::Posterior,
            (Criterion::Variance, false) => Stage::Geometric,
        };
        let spread_first = poses.len() < options.space_filling;
        let score = |c: usize| match stage {
            Stage::Maximin => nearest[c],
            _ if spread_first => gp.variance(c),
            _ => gp.gain(c),
        };
        let uniform = options.random_every > 0 && (poses.len() + 1) % options.random_every == 0;
        let best = match uniform {
            true => (user_count..count_c).chain(0..user_count).find(|&c| !chosen[c]).map(|c| (c, 0.0)),
            false => (0..count_c).filter(|&c| !chosen[c]).map(|c| (c, score(c))).max_by(|a, b| a.1.total_cmp(&b.1)),
        };
        let Some((c, _)) = best else { break };
        chosen[c] = true;
        if options.criterion == Criterion::Maximin {
            let q = kept[c * n..(c + 1) * n].to_vec();
            for (i, d) in nearest.iter_mut().enumerate() {
                *d = d.min(joint_distance2(&kept[i * n..(i + 1) * n], &q, &full_turn));
            }
        }
        batch.push(c);
        if let Some(g) = geometric.as_mut() {
            g.add(c);
        }
        gp.add(c);
        let predicted_rms = predict(&gp, &geometric);
        if predicted_rms.is_some() && geometric_identified_after.is_none() {
            geometric_identified_after = Some(poses.len() + 1);
        }
        poses.push(pose(c, stage, predicted_rms));
    }
    let mut exchange_swaps = 0;
    // Exchange passes improve the variance criterion; a maximin design is left as it is.
    if options.exchange > 0 && options.criterion == Criterion::Variance && !batch.is_empty() {
        // The candidates (and measured poses) as a fresh process tracks them: [candidates |
        // workspace | conditioned measured poses], conditioned on the measured poses and `batch`.
        let candidate_points = |prior: &Prior| -> Vec<posterior::Point> {
            (0..count_c).map(|i| prior.point(nominal, &all[i * n..(i + 1) * n], basis(i))).collect()
        };
        let measured_points = |prior: &Prior| -> Vec<posterior::Point> {
            conditioned.iter().map(|&i| prior.point(nominal, &measured_joints[i * n..(i + 1) * n], basis(measured_start + i))).collect()
        };
        let conditioned_on = |mut points: Vec<posterior::Point>, workspace: usize, prior: Prior, batch: &[usize]| -> Posterior {
            points.extend(measured_points(&prior));
            let mut gp = Posterior::new(prior, points, count_c, workspace);
            (0..conditioned.len()).for_each(|k| {
                gp.add(count_c + workspace + k);
            });
            batch.iter().for_each(|&c| {
                gp.add(c);
            });
            gp
        };
        // Each pass on a process built afresh (the first on the greedy step's when it shares its
        // workspace), so the rows a pass's swaps append are dropped after it.
        let mut current = gp;
        for pass in 0..options.exchange {
            if pass > 0 || options.exchange_workspace > 0 {
                // Frees the last process before the next is built.
                drop(std::mem::replace(&mut current, Posterior::new(Prior::new(&input.hyperparameters, m), Vec::new(), 0, 0)));
                let prior = Prior::new(&input.hyperparameters, m);
                let mut points = candidate_points(&prior);
                let size = match options.exchange_workspace {
                    0 => {
                        points.extend((count_c..count_c + count_w).map(|i| prior.point(nominal, &all[i * n..(i + 1) * n], basis(i))));
                        count_w
                    }
                    size => {
                        let seed = options.seed.wrapping_add(3 + pass as u64);
                        let sample = to_model(&candidates::uniform_within(input.limits, size, seed));
                        let jac = crate::parametric::identification_jacobian(nominal, &sample).map(|(jac, _)| jac);
                        points.extend(sample.chunks_exact(n).enumerate().map(|(w, q)| {
                            // The basis at a new point: its DH rows through the same scaling and prior factor.
                            let row = match (&rows, &jac) {
                                (Some(g), Some(jac)) => g.scaled_rows(jac, w),
                                _ => Vec::new(),
                            };
                            prior.point(nominal, q, times_factor(&row, &factor, m, p))
                        }));
                        size
                    }
                };
                current = conditioned_on(points, size, prior, &batch);
            }
            let swaps = exchange::pass(&mut current, &mut batch, &mut chosen);
            exchange_swaps += swaps;
            if swaps == 0 {
                break;
            }
        }
        drop(current);
        // The learning curve of the exchanged batch, in its order: a process on [batch | evaluation
        // | conditioned measured poses].
        let prior = Prior::new(&input.hyperparameters, m);
        let mut points: Vec<_> = batch.iter().map(|&c| prior.point(nominal, &all[c * n..(c + 1) * n], basis(c))).collect();
        points.extend(eval_range.clone().map(|i| prior.point(nominal, &all[i * n..(i + 1) * n], basis(i))));
        points.extend(measured_points(&prior));
        let (count_b, curve_eval) = (batch.len(), batch.len()..batch.len() + count_e);
        let mut curve = Posterior::new(prior, points, 0, 0);
        (0..conditioned.len()).for_each(|k| {
            curve.add(count_b + count_e + k);
        });
        let mut g = geometric_measured;
        geometric_identified_after = identified(&g).then_some(0);
        poses.clear();
        for (k, &c) in batch.iter().enumerate() {
            let stage = if identified(&g) { Stage::Posterior } else { Stage::Geometric };
            if let Some(g) = g.as_mut() {
                g.add(c);
            }
            curve.add(k);
            let predicted_rms = identified(&g).then(|| curve.mean_variance(curve_eval.clone()).sqrt());
            if predicted_rms.is_some() && geometric_identified_after.is_none() {
                geometric_identified_after = Some(k + 1);
            }
            poses.push(pose(c, stage, predicted_rms));
        }
    }
    Ok(Plan {
        poses,
        measured_predicted_rms,
        prior_rms_cbd,
        candidates: count_c,
        rejected_singular,
        geometric_parameters: p,
        geometric_identified_after,
        exchange_swaps,
        reach,
        hyperparameters: input.hyperparameters.clone(),
        seconds: start.elapsed().as_secs_f64(),
    })
}

/// G = J L (m × p, row-major): a point's scaled geometric rows J through the prior factor L.
fn times_factor(j: &[f64], factor: &[f64], m: usize, p: usize) -> Vec<f64> {
    if j.is_empty() {
        return Vec::new();
    }
    (0..m * p).map(|k| (0..p).map(|t| j[(k / p) * p + t] * factor[t * p + k % p]).sum()).collect()
}

#[cfg(test)]
mod tests;

/// Squared distance between two configurations in joint angle (model units), each joint's
/// difference taken around the circle where `full_turn`.
fn joint_distance2(a: &[f64], b: &[f64], full_turn: &[bool]) -> f64 {
    a.iter()
        .zip(b)
        .enumerate()
        .map(|(j, (x, y))| {
            let t = (x - y).abs();
            let t = if full_turn.get(j).copied().unwrap_or(false) {
                let t = t.rem_euclid(std::f64::consts::TAU);
                t.min(std::f64::consts::TAU - t)
            } else {
                t
            };
            t * t
        })
        .sum()
}

//! `cbd diagnose`: find the structure left in a model's residual, trace it to physical effects of
//! a library, keep the effects that hold up out of sample, and report the error before and after.
//!
//! Stages (one file each): residual structure tests (`structure`, `f_test`) → library Jacobians
//! (`library`, `kinematics`) → cross-validated forward selection (`selection`) → Gauss–Newton
//! refinement with uncertainties (`refine`), dropping what is not significant or does not earn its
//! place → held-out comparison and report (`report`); beside them, whether what is left follows
//! the order of measurement (`drift`).

pub mod error;
pub mod f_test;
pub mod kinematics;
pub mod library;
pub mod refine;
pub mod report;
pub mod selection;
pub mod structure;
#[cfg(test)]
mod test_effect;

use crate::calibrate::drift_test as drift;
use crate::data::Measurements;
use crate::evaluation::correction::{fit_on, CorrectionFitter};
use crate::nominal::positions;
use crate::parametric::independent_columns;
use crate::report::stats::ErrorStats;
use cbd_protocol::NominalModel;
pub use error::DiagnoseError;
use library::{candidate_groups, jacobian, Group, GroupKind, LibraryOptions, Param};
use selection::{forward_select, LinearProblem, Selection, SelectionOptions};
use structure::{structure_tests, StructureOptions, StructureTest};

/// Settings of a diagnosis.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DiagnoseOptions {
    pub library: LibraryOptions,
    pub selection: SelectionOptions,
    pub structure: StructureOptions,
    /// Share of the rows held out when no test set is given.
    pub holdout_fraction: f64,
    /// Geometric columns whose part orthogonal to the others is below this (relative) are
    /// unidentifiable and stay at their nominal values.
    pub identifiability_tolerance: f64,
    pub gauss_newton_iterations: usize,
    /// Folds of the cross-validation that recommends CbD's base (nominal or nominal + effects);
    /// 0 skips it.
    pub recommendation_folds: usize,
    /// The test for drift in measurement order.
    pub drift: drift::DriftOptions,
}

impl Default for DiagnoseOptions {
    fn default() -> Self {
        DiagnoseOptions {
            library: LibraryOptions::default(),
            selection: SelectionOptions::default(),
            structure: StructureOptions::default(),
            holdout_fraction: 0.2,
            identifiability_tolerance: 1e-5,
            gauss_newton_iterations: 10,
            recommendation_folds: 3,
            drift: drift::DriftOptions::default(),
        }
    }
}

/// One parameter of a found effect.
#[derive(Debug, Clone, PartialEq)]
pub struct FoundParameter {
    pub name: String,
    pub param: Param,
    pub value: f64,
    pub std_error: f64,
}

/// An effect group the selection kept.
#[derive(Debug, Clone, PartialEq)]
pub struct FoundEffect {
    pub name: String,
    pub kind: GroupKind,
    /// 0-based joint (link, for bending); `None` for geometric.
    pub joint: Option<usize>,
    pub parameters: Vec<FoundParameter>,
    /// Share of the training residual sum of squares of the starting model that this group
    /// explains when added in selection order (SSE before it minus SSE after, over the start's).
    pub share: f64,
    /// What the report calls "explains": the drop in residual variance when this group is added
    /// last (SSE without it minus SSE with all, over SSE without it).
    pub partial_share: f64,
    /// Cross-validated RMS position error after this group was added (selection order).
    pub cv_rms: f64,
}

/// One line of the held-out table.
#[derive(Debug, Clone, PartialEq)]
pub struct TableRow {
    pub name: String,
    pub stats: ErrorStats,
    pub errors: Vec<f64>,
    /// With several tool points per pose: the errors per point and of the tool frame.
    pub pose: Option<crate::evaluation::pose_errors::PoseErrors>,
}

/// Everything a diagnosis found.
#[derive(Debug, Clone)]
pub struct Diagnosis {
    pub train_rows: usize,
    pub test_rows: usize,
    /// `test set` or `held-out split`.
    pub held_out: &'static str,
    pub structure_before: Vec<StructureTest>,
    pub structure_after: Vec<StructureTest>,
    pub selection: Selection,
    pub candidates: usize,
    /// Names of all candidate groups (indices of `selection`).
    pub group_names: Vec<String>,
    /// The selection's margin (relative CV drop a group needed).
    pub margin: f64,
    pub found: Vec<FoundEffect>,
    /// Effects the selection chose that refinement showed not significant or not earning their place.
    pub dropped: Vec<DroppedEffect>,
    /// The model with the found effects (geometric corrections in the chain, effects listed).
    pub model_after: NominalModel,
    /// The geometric corrections refitted alone: the held-out "nominal + geometric" row's model
    /// (the start when none were found, `model_after` when nothing else was).
    pub model_geometric: NominalModel,
    /// Structure still significant after the effects: CbD is what absorbs it.
    pub unexplained_structure: bool,
    pub table: Vec<TableRow>,
    /// The held-out rows' noise floor (with CbD: σ from its evidence on nominal + effects).
    pub noise_floor: Option<crate::report::noise_floor::NoiseFloor>,
    /// Training residual (row-major) of the starting model and of `model_after`.
    pub residual_before: Vec<f64>,
    pub residual_after: Vec<f64>,
    /// Training rows actually used (after any held-out split).
    pub train: Measurements,
    /// The model the library's parameters change: the given model, or a planar arm's DH form
    /// (`nominal::planar::as_dh`, read in the data's two coordinates).
    pub model_start: NominalModel,
    /// With CbD: which base CbD should deform, by k-fold cross-validation on the training rows.
    pub recommendation: Option<Recommendation>,
    /// Drift in measurement order: the residual of `model_after` on every row of the data in file
    /// order (`None`: too few poses to test).
    pub drift: Option<drift::Drift>,
}

/// The pipeline `diagnose` recommends: CbD on the nominal model or on nominal + effects, whichever
/// predicts held-out training folds better (never the test rows).
#[derive(Debug, Clone, PartialEq)]
pub struct Recommendation {
    /// Per candidate (table name): RMS position error on the held-out folds.
    pub cross_validation: Vec<(String, f64)>,
    pub folds: usize,
    /// The candidate with the least error.
    pub best: String,
    /// Naming the effects made the final model worse out of sample.
    pub effects_hurt: bool,
}

/// RMS held-out error of `fit` on `base` over `folds` interleaved folds of `train`.
fn cross_validated_rms(fit: CorrectionFitter, base: &NominalModel, train: &Measurements, folds: usize) -> crate::Result<f64> {
    let (mut sse, mut count) = (0.0, 0usize);
    for fold in 0..folds {
        let (rest, held) = train.fold(folds, fold);
        let predict = fit_on(fit, base, &rest)?.predict;
        sse += predict(&held.joints).iter().zip(&held.positions).map(|(a, b)| (a - b).powi(2)).sum::<f64>();
        count += held.len();
    }
    Ok((sse / count.max(1) as f64).sqrt())
}

impl Diagnosis {
    /// The found effects other than geometric corrections.
    pub fn physical_effects(&self) -> Vec<&FoundEffect> {
        self.found.iter().filter(|f| f.kind != GroupKind::Geometric).collect()
    }

    pub fn row(&self, name: &str) -> Option<&TableRow> {
        self.table.iter().find(|r| r.name == name)
    }
}

/// Why an effect the selection chose was dropped after refinement.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum DropReason {
    /// Its estimate is within 3 standard errors of zero (Wald p > 0.0027).
    NotSignificant,
    /// Added last, it lowers the cross-validated error by less than the margin.
    NoCrossValidatedGain,
    /// A function of its joint's angle alone, and that joint's deflection still has structure
    /// after it (the joint-shape test): the library fits part of a shape it does not have.
    ShapeOutsideLibrary,
}

/// An effect dropped after refinement.
#[derive(Debug, Clone, PartialEq)]
pub struct DroppedEffect {
    pub group: usize,
    pub name: String,
    pub reason: DropReason,
    /// Wald test of all its parameters being zero.
    pub p_value: f64,
    /// Relative drop of the cross-validated RMS when it is added last.
    pub cv_gain: f64,
}

/// Smallest Wald p-value an effect may have: 3 standard errors (two-sided normal tail).
pub const SIGNIFICANCE: f64 = 0.0027;

/// Group `g` (among the refined `chosen_cols`, whose cross-validated RMS is `cv_with`) when it is
/// not significant or does not earn its place; `None` when it stays.
fn judge(
    g: usize,
    group_cols: &[Vec<usize>],
    chosen_cols: &[usize],
    refined: &refine::Refined,
    problem: &LinearProblem,
    cv_with: f64,
    margin: f64,
) -> Option<DroppedEffect> {
    let positions: Vec<usize> = group_cols[g].iter().filter_map(|c| chosen_cols.iter().position(|k| k == c)).collect();
    let p_value = refined.wald_p_value(&positions);
    let without: Vec<usize> = chosen_cols.iter().copied().filter(|c| !group_cols[g].contains(c)).collect();
    let cv_gain = 1.0 - cv_with / problem.cv_rms(&without).max(f64::MIN_POSITIVE);
    // Written so that a NaN p-value (a singular covariance block) is not significant.
    let reason = if !(p_value <= SIGNIFICANCE) {
        DropReason::NotSignificant
    } else if cv_gain < margin {
        DropReason::NoCrossValidatedGain
    } else {
        return None;
    };
    Some(DroppedEffect { group: g, name: String::new(), reason, p_value, cv_gain })
}

/// The first kept joint deflection (encoder scale, transmission, gravity compliance) on a joint
/// whose deflection the joint-shape test still finds structured after the refined effects: what
/// the library names there is part of a shape it does not have. (Gravity compliance too: its
/// regressor holds the joint's own first harmonic and those of the links after it, flexible
/// enough to take a share of a localized bump.)
fn shape_outside_library(
    train: &Measurements,
    refined: &refine::Refined,
    kept: &[usize],
    groups: &[Group],
    options: &StructureOptions,
) -> Option<DroppedEffect> {
    let is_joint_deflection = |g: &usize| groups[*g].effect_kind().is_some_and(|k| !k.task_space());
    if !kept.iter().any(is_joint_deflection) {
        return None;
    }
    let tests = structure_tests(&refined.model, train, &train.residual_of(&refined.model), options);
    kept.iter().filter(|g| is_joint_deflection(g)).find_map(|&g| {
        let shape = tests.iter().find(|t| t.family == "joint shape" && t.joint == groups[g].joint && t.significant)?;
        Some(DroppedEffect {
            group: g,
            name: String::new(),
            reason: DropReason::ShapeOutsideLibrary,
            p_value: shape.test.p_value,
            cv_gain: f64::NAN,
        })
    })
}

/// Splits `data` into (fit, held-out) rows: unordered rows by a seeded permutation; measured rows
/// ([`crate::data::RowOrder`]) as one contiguous block of poses placed by the seed, the poses within
/// the gap of it in neither set (a held-out pose with training neighbours in time flatters every model).
pub fn holdout_split(data: &Measurements, fraction: f64, seed: u64) -> (Measurements, Measurements) {
    use rand::seq::SliceRandom;
    use rand::{Rng, SeedableRng};
    // By whole poses (a pose's tool points stay together).
    let poses = data.pose_count();
    let held = ((poses as f64 * fraction).round() as usize).clamp(1, poses.saturating_sub(2).max(1));
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let (train, test): (Vec<usize>, Vec<usize>) = match data.order {
        crate::data::RowOrder::Unordered => {
            let mut order: Vec<usize> = (0..poses).collect();
            order.shuffle(&mut rng);
            let (test, train) = order.split_at(held);
            let (mut train, mut test) = (train.to_vec(), test.to_vec());
            train.sort_unstable();
            test.sort_unstable();
            (train, test)
        }
        crate::data::RowOrder::Measured => {
            let start = rng.gen_range(0..=poses - held);
            let out = crate::data::with_gap(start..start + held, poses);
            ((0..poses).filter(|k| !out.contains(k)).collect(), (start..start + held).collect())
        }
    };
    (data.subset(&data.pose_rows(&train)), data.subset(&data.pose_rows(&test)))
}

/// Columns of each group that enter the selection: geometric pruned to an identifiable set, a
/// gravity regressor pruned to the combinations identifiable beside the geometric columns, other
/// groups' columns kept when not (numerically) zero and not in the span of the identifiable
/// geometric columns.
fn usable_columns(groups: &[Group], offsets: &[usize], jac: &faer::Mat<f64>, tol: f64) -> Vec<Vec<usize>> {
    let norms: Vec<f64> = (0..jac.ncols()).map(|k| (0..jac.nrows()).map(|i| jac[(i, k)].powi(2)).sum::<f64>().sqrt()).collect();
    // A column of rounding noise (e.g. the gravity torque about a vertical axis) is zero:
    // compare with the largest column of the same effect type.
    let mut largest = std::collections::BTreeMap::new();
    for (g, group) in groups.iter().enumerate() {
        let e = largest.entry(group.kind.type_name()).or_insert(0.0f64);
        *e = norms[offsets[g]..offsets[g] + group.params.len()].iter().fold(*e, |a, &b| a.max(b));
    }
    let mut geometric: Vec<usize> = Vec::new();
    groups
        .iter()
        .enumerate()
        .map(|(g, group)| {
            let cols: Vec<usize> = (offsets[g]..offsets[g] + group.params.len())
                .filter(|&k| norms[k] > 1e-9 * largest[group.kind.type_name()] && norms[k] > 0.0)
                .collect();
            if group.kind == GroupKind::Geometric {
                geometric = independent_columns(jac.as_ref(), &norms, &cols, tol);
                geometric.clone()
            } else if group.effect_kind().is_some_and(|k| k.regressor()) {
                // The gravity regressor's identifiable combinations: the columns column-pivoted
                // QR keeps beside the geometric ones (the others are fitted as zero).
                let with: Vec<usize> = geometric.iter().chain(&cols).copied().collect();
                independent_columns(jac.as_ref(), &norms, &with, tol).into_iter().filter(|c| cols.contains(c)).collect()
            } else {
                let with: Vec<usize> = geometric.iter().chain(&cols).copied().collect();
                let kept = independent_columns(jac.as_ref(), &norms, &with, tol);
                if cols.iter().all(|c| kept.contains(c)) {
                    cols
                } else {
                    Vec::new()
                }
            }
        })
        .collect()
}

/// Diagnoses `model` (nominal plus any effects it already declares) on `data`. Held-out rows:
/// `test` when given, otherwise a split of `data`. `cbd` fits the nonparametric correction for
/// the table's CbD rows (skipped when `None`). A planar arm is diagnosed as its DH form, so that
/// its geometric group holds base translation and rotation, joint offsets and link lengths.
pub fn diagnose(
    given: &NominalModel,
    data: &Measurements,
    test: Option<&Measurements>,
    cbd: Option<CorrectionFitter>,
    options: &DiagnoseOptions,
) -> Result<Diagnosis, DiagnoseError> {
    let given_test = test.is_some();
    let (train, test, held_out) = match test {
        Some(t) => (data.clone(), t.clone(), "test set"),
        None => {
            let (a, b) = holdout_split(data, options.holdout_fraction, options.selection.seed.wrapping_add(17));
            (a, b, "held-out split")
        }
    };
    if train.len() < 10 {
        let held_out = if given_test { 0 } else { data.len() - train.len() };
        return Err(DiagnoseError::TooFewRows { got: train.len(), rows: data.len(), held_out });
    }
    let m = given.task_dim();
    if train.task_dim != m || test.task_dim != m {
        return Err(DiagnoseError::TaskDimension { model: m, train: train.task_dim, test: test.task_dim });
    }
    let dh_form = crate::nominal::planar::as_dh(given);
    let model = &dh_form;
    // 1. Residuals of the current model and 2. their structure.
    let r0 = train.residual_of(model);
    let structure_before = structure_tests(model, &train, &r0, &options.structure);
    // 3. The library's columns at the current model.
    let groups = candidate_groups(model, &options.library, m);
    let params: Vec<Param> = groups.iter().flat_map(|g| g.params.clone()).collect();
    let mut offsets = Vec::with_capacity(groups.len());
    let mut at = 0;
    for g in &groups {
        offsets.push(at);
        at += g.params.len();
    }
    let jac = jacobian(model, &train, &params);
    let group_cols = usable_columns(&groups, &offsets, &jac, options.identifiability_tolerance);
    // 4. Selection, judged out of sample.
    let problem = LinearProblem::new(&jac, &r0, m, train.points_per_pose, train.order, options.selection.folds, options.selection.seed);
    let selection = forward_select(&problem, &group_cols, &options.selection);
    // 5. Refinement on the nonlinear model; then every effect must be significant and earn its
    // place, or it is dropped (the weakest first) and the rest refined again.
    let Pruned { kept, dropped, chosen_cols, start, full_sse, chosen_params, refined } =
        refine_and_prune(model, &train, &problem, &groups, &group_cols, &params, selection.selected.clone(), options)?;
    let base_sse = problem.base_sse().max(f64::MIN_POSITIVE);
    let step_of = |g: usize| selection.steps.iter().find(|s| s.group == g).expect("a kept group was selected");
    let found: Vec<FoundEffect> = kept
        .iter()
        .enumerate()
        .map(|(order, &g)| {
            let step = step_of(g);
            let earlier: Vec<usize> = kept[..order].iter().flat_map(|&e| group_cols[e].clone()).collect();
            let with: Vec<usize> = earlier.iter().chain(&group_cols[g]).copied().collect();
            let gain = problem.fit(&earlier).1 - problem.fit(&with).1;
            let without: Vec<usize> = chosen_cols.iter().copied().filter(|c| !group_cols[g].contains(c)).collect();
            let (_, sse_without) = problem.fit(&without);
            let parameters = group_cols[g]
                .iter()
                .map(|c| {
                    let pos = chosen_cols.iter().position(|k| k == c).expect("chosen");
                    FoundParameter {
                        name: library::param_name(model, &params[*c]),
                        param: params[*c],
                        value: refined.values[pos],
                        std_error: refined.std_errors[pos],
                    }
                })
                .collect();
            FoundEffect {
                name: groups[g].name.clone(),
                kind: groups[g].kind,
                joint: groups[g].joint,
                parameters,
                share: (gain / base_sse).max(0.0),
                partial_share: ((sse_without - full_sse) / sse_without.max(f64::MIN_POSITIVE)).max(0.0),
                cv_rms: step.cv_rms,
            }
        })
        .collect();
    // 6. Structure left after the effects.
    let r1 = train.residual_of(&refined.model);
    let structure_after = structure_tests(&refined.model, &train, &r1, &options.structure);
    let unexplained_structure = structure_after.iter().any(|t| t.significant);
    // Drift: the first rows of the data in file order (the held-out split is a random subset),
    // the refined parameters marginalised through their Jacobian there.
    let revolute: Vec<bool> = (0..model.n_joints()).map(|d| model.is_revolute(d)).collect();
    let tested = data.subset(&(0..data.len().min(options.drift.window.saturating_mul(data.points_per_pose.max(1)))).collect::<Vec<_>>());
    let fitted = jacobian(&refined.model, &tested, &chosen_params);
    let drift = drift::drift_test(&tested, &revolute, &tested.residual_of(&refined.model), Some(fitted.as_ref()), &options.drift);
    // 7. Held-out table and the recommendation.
    let geometric_only = geometric_only_model(model, &found, &refined, &chosen_params, &start, &train, options)?;
    let (table, cbd_sigma) = held_out_table(given, model, &geometric_only, &refined.model, &train, &test, cbd)?;
    // The floor of the held-out rows: σ by CbD's evidence on nominal + effects (its last row's model).
    let noise_floor =
        cbd_sigma.map(|s| crate::report::noise_floor::NoiseFloor::new(s, given.task_dim(), "CbD's evidence on nominal + effects"));
    let recommendation = match cbd {
        Some(fit) if !found.is_empty() && options.recommendation_folds >= 2 => {
            Some(recommend(fit, given, &refined.model, &train, options.recommendation_folds)?)
        }
        _ => None,
    };
    Ok(Diagnosis {
        train_rows: train.len(),
        test_rows: test.len(),
        held_out,
        structure_before,
        structure_after,
        candidates: group_cols.iter().filter(|c| !c.is_empty()).count(),
        selection,
        margin: options.selection.margin,
        group_names: groups.iter().map(|g| g.name.clone()).collect(),
        found,
        dropped,
        model_after: refined.model,
        model_geometric: geometric_only,
        unexplained_structure,
        table,
        noise_floor,
        residual_before: r0,
        residual_after: r1,
        train,
        model_start: dh_form.clone(),
        recommendation,
        drift,
    })
}

/// The selected groups after refinement and pruning: what stays, what was dropped and why, and
/// the refined fit of what stays.
struct Pruned {
    kept: Vec<usize>,
    dropped: Vec<DroppedEffect>,
    chosen_cols: Vec<usize>,
    start: Vec<f64>,
    full_sse: f64,
    chosen_params: Vec<Param>,
    refined: refine::Refined,
}

/// Stage 5: refine the selected groups on the nonlinear model; every non-geometric effect must be
/// significant and earn its place, or the weakest is dropped and the rest refined again.
#[allow(clippy::too_many_arguments)]
fn refine_and_prune(
    model: &NominalModel,
    train: &Measurements,
    problem: &LinearProblem,
    groups: &[Group],
    group_cols: &[Vec<usize>],
    params: &[Param],
    selected: Vec<usize>,
    options: &DiagnoseOptions,
) -> Result<Pruned, DiagnoseError> {
    let mut kept = selected;
    let mut dropped = Vec::new();
    let pruned = loop {
        let chosen_cols: Vec<usize> = kept.iter().flat_map(|&g| group_cols[g].clone()).collect();
        let (start, full_sse) = problem.fit(&chosen_cols);
        let chosen_params: Vec<Param> = chosen_cols.iter().map(|&k| params[k]).collect();
        let refined = refine::refine(model, train, &chosen_params, &start, options.gauss_newton_iterations)?;
        let cv_with = problem.cv_rms(&chosen_cols);
        let weakest = kept
            .iter()
            .filter(|&&g| groups[g].kind != GroupKind::Geometric)
            .filter_map(|&g| judge(g, group_cols, &chosen_cols, &refined, problem, cv_with, options.selection.margin))
            .max_by(|a, b| a.p_value.total_cmp(&b.p_value))
            .or_else(|| shape_outside_library(train, &refined, &kept, groups, &options.structure));
        match weakest {
            Some(mut d) => {
                kept.retain(|&g| g != d.group);
                d.name = groups[d.group].name.clone();
                dropped.push(d);
            }
            None => break Pruned { kept, dropped, chosen_cols, start, full_sse, chosen_params, refined },
        }
    };
    Ok(pruned)
}

/// The model the "+ geometric" row evaluates: the geometric parameters refitted alone (what a
/// geometric calibration gives), or the refined model when geometry is all that was found.
fn geometric_only_model(
    model: &NominalModel,
    found: &[FoundEffect],
    refined: &refine::Refined,
    chosen_params: &[Param],
    start: &[f64],
    train: &Measurements,
    options: &DiagnoseOptions,
) -> Result<NominalModel, DiagnoseError> {
    if !found.iter().any(|f| f.kind == GroupKind::Geometric) {
        return Ok(model.clone());
    }
    if found.len() == 1 {
        return Ok(refined.model.clone());
    }
    let gp: Vec<Param> = chosen_params.iter().copied().filter(|p| matches!(p, Param::Geometric(_))).collect();
    let gs: Vec<f64> = chosen_params.iter().zip(start).filter(|(p, _)| matches!(p, Param::Geometric(_))).map(|(_, v)| *v).collect();
    Ok(refine::refine(model, train, &gp, &gs, options.gauss_newton_iterations)?.model)
}

/// The held-out rows in the order the corrections build up: nominal → + geometric → + effects →
/// + effects + CbD; and CbD alone on the nominal (the CbD rows only when `cbd` is given); and the
/// noise σ CbD's evidence estimated on nominal + effects.
fn held_out_table(
    given: &NominalModel,
    model: &NominalModel,
    geometric_only: &NominalModel,
    with_effects: &NominalModel,
    train: &Measurements,
    test: &Measurements,
    cbd: Option<CorrectionFitter>,
) -> Result<(Vec<TableRow>, Option<f64>), DiagnoseError> {
    // The file's task dimension: a planar arm's DH form (`model`) is read in its two coordinates.
    let m = given.task_dim();
    let mut table = Vec::new();
    let mut push = |name: &str, predicted: Vec<f64>| {
        let errors = crate::report::stats::position_errors(&predicted, &test.positions, m);
        let pose = crate::evaluation::pose_errors::PoseErrors::of(given.tool_points(), &predicted, &test.positions, m);
        table.push(TableRow { name: name.to_string(), stats: ErrorStats::of_errors(&errors), errors, pose });
    };
    push("nominal", positions(model, &test.joints, m));
    push("nominal + geometric", positions(geometric_only, &test.joints, m));
    push("nominal + effects", positions(with_effects, &test.joints, m));
    let mut sigma = None;
    if let Some(fit) = cbd {
        // The effects are in the model's nominal chain, which the runtime evaluates: CbD fits on top.
        let on_effects = fit_on(fit, with_effects, train).map_err(DiagnoseError::on_effects)?;
        sigma = on_effects.noise_sigma;
        push("nominal + effects + CbD", (on_effects.predict)(&test.joints));
        let plain = fit(given, train).map_err(DiagnoseError::on_nominal)?.predict;
        push("nominal + CbD", plain(&test.joints));
    }
    Ok((table, sigma))
}

/// Whether CbD does better on top of the found effects or on the nominal model alone, judged by
/// `folds`-fold cross-validation on the training rows.
fn recommend(
    fit: CorrectionFitter,
    given: &NominalModel,
    with_effects: &NominalModel,
    train: &Measurements,
    folds: usize,
) -> Result<Recommendation, DiagnoseError> {
    let on_effects = cross_validated_rms(fit, with_effects, train, folds).map_err(DiagnoseError::on_effects)?;
    let plain = cross_validated_rms(fit, given, train, folds).map_err(DiagnoseError::on_nominal)?;
    let effects_hurt = plain < on_effects;
    Ok(Recommendation {
        cross_validation: vec![("nominal + effects + CbD".into(), on_effects), ("nominal + CbD".into(), plain)],
        folds,
        best: if effects_hurt { "nominal + CbD" } else { "nominal + effects + CbD" }.into(),
        effects_hurt,
    })
}

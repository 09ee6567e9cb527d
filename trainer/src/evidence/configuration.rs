//! The configuration-dependent task term chosen by evidence (docs/DESIGN.md §16, Trainer): CbD's
//! two fields alone against the same with γ_C K̃_Q(q, q') K̃_X(k0, k0') I, each searched by type-II
//! maximum likelihood in the kernel form on the same evenly spaced rows, and the term kept only when
//! it gains more than ½ ln(N m) nats per added hyperparameter (the BIC's price: the plain model is
//! the term's γ_C → 0, so the richer family never scores lower at its optimum).

use super::search::{counted, from_each, minimise, Criterion, Partial};
use super::table::{ConfigTheta, DataScales, PairTable, Theta};
use super::{CbdHyperparameters, EvidenceError, EvidenceOptions};
use crate::data::stage_rows::EvidenceRows;
use crate::data::Measurements;
use crate::numeric::likelihood_search::LikelihoodSearch;
use cbd_protocol::{NominalModel, Normalisation};
use std::cell::RefCell;

/// What the comparison found (the JSON's `configuration_field`).
#[derive(Debug, Clone, serde::Serialize)]
pub struct ConfigurationEvidence {
    /// Whether the evidence chose the term.
    pub chosen: bool,
    /// Why a term the evidence chose is not in the model (`None`: it is, or was not chosen).
    pub not_used: Option<String>,
    /// Log evidence without and with the term, nats, data units, on `rows` rows.
    pub plain_log_evidence: f64,
    pub with_term_log_evidence: f64,
    /// The gain the term had to exceed: ½ ln(N m) per added hyperparameter.
    pub margin: f64,
    pub added_hyperparameters: usize,
    pub rows: usize,
    /// The hyperparameters with the term (its search's optimum), whether chosen or not.
    pub with_term: CbdHyperparameters,
    /// Widths that ended at a bound of the search's box (the task width's upper bound: flat).
    pub at_bounds: Vec<String>,
    pub evaluations: usize,
    pub seconds: f64,
}

impl ConfigurationEvidence {
    /// One line: the decision and both scores.
    pub fn describe(&self) -> String {
        let what = match (&self.not_used, self.chosen) {
            (Some(why), _) => format!("off ({why}; chosen"),
            (None, true) => "on (chosen".into(),
            (None, false) => "off (not chosen".into(),
        };
        let bounds = if self.at_bounds.is_empty() { String::new() } else { format!("; at bounds: {}", self.at_bounds.join(", ")) };
        format!(
            "configuration field: {what} by evidence: log evidence without {:.1}, with {:.1} on {} rows; gain {:+.1} against the margin {:.1} = ½ ln(N m) × {} hyperparameters{bounds})",
            self.plain_log_evidence,
            self.with_term_log_evidence,
            self.rows,
            self.with_term_log_evidence - self.plain_log_evidence,
            self.margin,
            self.added_hyperparameters
        )
    }
}

/// The kernel form's evidence with tighter stopping rules (1e-6 nats per unknown of change, 1e-5 of
/// gradient): with the term's 2n + 6 hyperparameters the optimum lies along flat ridges, where the
/// plain search's 1e-4 per unknown stopped after a few iterations (UR5: 159 evaluations for 8 starts,
/// 19 nats of gain where the prototype found 45–100). Ten times looser than the 1e-7 / 1e-6 first
/// used: on the UR5's ten folds the same basins and errors (blocked 0.0718 against 0.0720 mm,
/// interleaved 0.0634 against 0.0636, the field kept on all ten) for a fifth less of the fit's CPU
/// time (docs/DESIGN.md §16 "The search's cost").
struct Tight<'a>(&'a PairTable);

impl Criterion for Tight<'_> {
    fn observations(&self) -> usize {
        self.0.observations()
    }
    fn nlml_and_gradient(&self, packed: &[f64]) -> Option<(f64, Vec<f64>)> {
        self.0.nlml_and_gradient(packed)
    }
    fn nlml(&self, packed: &[f64]) -> Option<(f64, Partial)> {
        self.0.nlml(packed)
    }
    fn gradient_from(&self, packed: &[f64], partial: Partial) -> Option<Vec<f64>> {
        self.0.gradient_from(packed, partial)
    }
    fn tolerances(&self) -> (f64, f64) {
        (1e-6, 1e-5)
    }
}

/// L-BFGS restarted from where it stopped (its curvature memory cleared) until a restart gains less
/// than `RESTART_GAIN` nats, at most `RESTARTS` times: argmin's L-BFGS, with a backtracking line
/// search and the box as a quadratic wall, stops early on the flat ridges and near the box's faces
/// where the evidence's optima lie (UR5 interleaved fold 0: the plain member's search stopped 99 nats
/// below the optimum scipy's L-BFGS-B reaches from the same point).
fn minimise_restarted(
    criterion: &dyn Criterion,
    lower: &[f64],
    upper: &[f64],
    from: &[f64],
    iterations: u64,
    evaluations: &RefCell<usize>,
) -> Option<(f64, Vec<f64>)> {
    let mut best = minimise(criterion, lower, upper, from, iterations, evaluations)?;
    for _ in 0..RESTARTS {
        match minimise(criterion, lower, upper, &best.1, iterations, evaluations) {
            Some(next) if next.0 < best.0 - RESTART_GAIN => best = next,
            Some(next) => {
                if next.0 < best.0 {
                    best = next;
                }
                break;
            }
            None => break,
        }
    }
    Some(best)
}

/// At most this many restarts of a refinement, each kept while it gains `RESTART_GAIN` nats.
const RESTARTS: usize = 4;
const RESTART_GAIN: f64 = 0.5;

/// Screened starts on the plain optimum found here (and the hand-over starts) that go on.
const REFINED_ON_THE_OPTIMUM: usize = 2;

/// Screened starts on the plain θ given and the balanced start that go on.
const REFINED: usize = 3;

/// Of the term's screened starts run to the end on the medium rows, the best continued on every row.
const TERM_CONTINUED: usize = 2;

/// The refinements' iteration limit (at least the plain search's): 2n + 6 hyperparameters along
/// flat ridges need more than the plain search's 80 (the prototype's L-BFGS-B: 300).
const REFINE_ITERATIONS: u64 = 300;

/// A log width within this of its box's face is "at the bound".
const AT_BOUND: f64 = 1e-2;

/// Searches the term on top of `plain` (CbD's hyperparameters for `nominal` on `data`, the fields
/// alone) and compares the two on the kernel form's evenly spaced rows, `rows` (the evidence's rows
/// of `data` for `options`: [`EvidenceRows::new`]).
pub fn search_configuration_term(
    nominal: &NominalModel,
    data: &Measurements,
    rows: &EvidenceRows,
    norm: &Normalisation,
    options: &EvidenceOptions,
    plain: &CbdHyperparameters,
) -> Result<ConfigurationEvidence, EvidenceError> {
    let start = std::time::Instant::now();
    if data.len() < crate::numeric::likelihood_search::MIN_SEARCH_ROWS {
        return Err(EvidenceError::TooFewRows(LikelihoodSearch::CbdEvidence, data.len()));
    }
    let used = &rows.used;
    let table = PairTable::new(nominal, used, norm);
    let coarse = rows.coarse.as_ref().map(|coarse| PairTable::new(nominal, coarse, norm));
    // The medium rows (half the evidence's unknowns, evenly spaced: each evaluation about an eighth of
    // the cost): starts far from their optimum climb there, and only the best go on on every row.
    // Data with no coarse rows (or medium rows no fewer than the coarse) search on every row.
    let medium = rows.medium.as_ref().map(|medium| PairTable::new(nominal, medium, norm));
    let n = table.n;
    let scales = DataScales::of(&table);
    let (lower, upper) = configuration_bounds(&scales, &table);
    let flat = upper[2 * n + 3];
    let evaluations = RefCell::new(0usize);
    // The plain model: its θ refined on these rows (it may come from every row in weight space).
    let plain_theta = Theta::from_user(plain, norm, flat);
    let plain_packed: Vec<f64> = plain_theta.pack();
    let (plain_lower, plain_upper) = scales.bounds(&table);
    let plain_at = table.nlml_and_gradient(&plain_packed).map(|(v, _)| (v, plain_packed.clone()));
    // The plain member refined on these rows from its chosen θ, with the tight rule and restarts (the
    // plain search stops at 1e-4 nats per unknown). The term is nested in the plain member, so its
    // gain is measured against this optimum, and its starts are put on top of it too. The plain
    // search's other starts are not searched again here: it screened them itself, and running each
    // to the end on the medium rows and the best on these (the search until stop 62, added when the
    // plain search ended 114 nats short on the UR5's interleaved fold 0) cost a fifth of dh+cbd's fit
    // on the UR5 and moved none of its ten folds by more than 1e-3 mm (docs/DESIGN.md §16, stop 63).
    let long = options.max_iterations.max(REFINE_ITERATIONS);
    let plain_tight = Tight(&table);
    let from_given = minimise_restarted(&plain_tight, &plain_lower, &plain_upper, &plain_packed, long, &evaluations);
    // Runs each start to the end on the medium rows, scores the optima on the evidence's rows (one
    // evaluation each) and continues the best `keep` there to the end; without medium rows, every
    // start on the evidence's rows. A start far from its optimum spends most of its evaluations
    // climbing (UR5: 80–390 on every row for a term's start), which the medium rows do at an eighth
    // of the cost; the evidence's rows then only finish it (30–70).
    // Each start's searches run on the command's workers (`from_each`), the results in the starts'
    // order, as a serial loop's.
    let staged = |from: &[Vec<f64>], keep: usize, evaluations: &RefCell<usize>| -> Vec<(f64, Vec<f64>)> {
        let full = Tight(&table);
        let to_the_end = |from: &[Vec<f64>]| -> Vec<(f64, Vec<f64>)> {
            from_each(from, evaluations, |p, counted| minimise_restarted(&full, &lower, &upper, p, long, counted))
                .into_iter()
                .flatten()
                .collect()
        };
        let Some(medium) = &medium else {
            return to_the_end(from);
        };
        let medium = Tight(medium);
        let mut scored: Vec<(f64, Vec<f64>)> = from_each(from, evaluations, |p, counted| {
            let (_, p) = minimise_restarted(&medium, &lower, &upper, p, long, counted)?;
            *counted.borrow_mut() += 1;
            table.nlml_and_gradient(&p).map(|(v, _)| (v, p))
        })
        .into_iter()
        .flatten()
        .collect();
        scored.sort_by(|a, b| a.0.total_cmp(&b.0));
        let kept: Vec<Vec<f64>> = scored.into_iter().take(keep).map(|(_, p)| p).collect();
        to_the_end(&kept)
    };
    let mut plain_found: Vec<(f64, Vec<f64>)> = from_given.into_iter().chain(plain_at).collect();
    plain_found.sort_by(|a, b| a.0.total_cmp(&b.0));
    let (plain_nlml, best_plain) = plain_found.into_iter().next().ok_or(EvidenceError::NoValidSetting(LikelihoodSearch::CbdEvidence))?;
    let best_plain_theta = Theta::unpack(&best_plain, n);
    // The term's starts: on top of the plain optimum, and on top of the plain search's balanced start
    // (the basin where the joint field stays smooth and the term takes the narrow joint widths, the
    // prototype's on the UR5), each with joint widths b = 5 and 0.5 (the prototype's) and a flat task
    // factor, a narrower task factor, and the term negligible (γ_C 1e-6 of the residual's variance:
    // the nested model's optimum is reachable).
    let var_r = table.fields_variance;
    let half = scales.log_half();
    let widths = |shift: f64| scales.widths(&table, shift);
    let fixed = |b: f64| -> Vec<f64> { table.joint.forms.iter().zip(half).map(|(f, l)| if f.periodic() { b.ln() } else { *l }).collect() };
    let balanced = Theta { log_sigma: plain_theta.log_sigma, ..scales.starts(&table)[0].clone() };
    // [b = 5, b = 0.5, narrower task factor, negligible term] on `base`.
    let starts_on = |base: &Theta| -> [Vec<f64>; 4] {
        let with = |log_widths: Vec<f64>, log_a: f64, gamma: f64| {
            Theta { config: Some(ConfigTheta { log_widths, log_a, log_gamma: (gamma * var_r).ln() }), ..base.clone() }.pack()
        };
        [with(fixed(5.0), flat, 0.3), with(fixed(0.5), flat, 0.3), with(widths(0.0), 0.5f64.ln(), 0.3), with(widths(0.0), flat, 1e-6)]
    };
    let on_given = starts_on(&plain_theta);
    let on_optimum_found = starts_on(&best_plain_theta);
    // The negligible term on the best plain optimum (see the screening below).
    let nested = on_optimum_found[3].clone();
    // Two groups, screened apart (below): the starts on the plain θ given and on the balanced start,
    // and those on the plain optimum found here with the hand-over starts.
    let given_group: Vec<Vec<f64>> = on_given.into_iter().chain(starts_on(&balanced)).collect();
    let mut optimum_group: Vec<Vec<f64>> = on_optimum_found.into();
    // Hand-over starts: for each joint the plain optimum made narrower than typical pairs, the term
    // takes that narrow width (its other widths smooth, a flat task factor) and the joint field's
    // width of that joint returns to the typical pair's. The plain member can be local in a joint
    // only through J K_V J'ᵀ; the term is the same locality without the Jacobian's structure, and
    // its optimum is found from there, not from equal widths (the prototype's UR5 basin: the term
    // narrow in joint 1, the joint field smooth in it).
    for d in 0..n {
        let slope = table.joint.forms[d].log_weight_slope();
        if (best_plain_theta.log_widths[d] - half[d]) * slope <= 0.0 {
            continue;
        }
        let mut term_widths = widths(-16f64.ln());
        term_widths[d] = best_plain_theta.log_widths[d];
        let mut base = best_plain_theta.clone();
        base.log_widths[d] = half[d];
        optimum_group.push(
            Theta { config: Some(ConfigTheta { log_widths: term_widths, log_a: flat, log_gamma: (0.3 * var_r).ln() }), ..base }.pack(),
        );
    }
    // Screening runs each start once; refinement restarts L-BFGS while it gains.
    let run =
        |table: &PairTable, from: &[Vec<f64>], iterations: u64, restarted: bool, evaluations: &RefCell<usize>| -> Vec<(f64, Vec<f64>)> {
            let table = Tight(table);
            let mut found: Vec<_> = from_each(from, evaluations, |p, counted| match restarted {
                true => minimise_restarted(&table, &lower, &upper, p, iterations, counted),
                false => minimise(&table, &lower, &upper, p, iterations, counted),
            })
            .into_iter()
            .flatten()
            .collect();
            found.sort_by(|a, b| a.0.total_cmp(&b.0));
            found
        };
    // Screened on the coarse rows; the screened starts run to the end on the medium rows and the best
    // two (scored on the evidence's rows) refined to the end there (issue 49 item 4: the UR5's basins
    // are close, so more than one goes on).
    // The negligible term on the plain optimum always goes on: the coarse rows can rank it last while
    // it is the nested model's optimum on these rows (UR5 block 4: the three screened ended 23 nats
    // below the plain model).
    // Screened in two groups, each ranked on its own: the starts on the plain θ given and the balanced
    // start (the best three go on), and those on the plain optimum found here, with the hand-over
    // starts (the best two go on): one ranking over all of them let the second group's starts, ahead
    // after a few coarse iterations, push out the start that leads to the highest optimum (UR5
    // interleaved fold 0: 1898 instead of 1975 nats).
    let screened: Vec<Vec<f64>> = match &coarse {
        Some(c) => {
            let best = |group: &[Vec<f64>], keep: usize| -> Vec<Vec<f64>> {
                run(c, group, options.screening_iterations, false, &evaluations).into_iter().take(keep).map(|(_, p)| p).collect()
            };
            let mut screened = best(&given_group, REFINED);
            screened.extend(best(&optimum_group, REFINED_ON_THE_OPTIMUM));
            screened
        }
        None => given_group.into_iter().chain(optimum_group).collect(),
    };
    // The negligible term on the best plain optimum goes on on every row (the nested model's optimum;
    // on the plain θ given it is the plain member searched again, which the plain search above did).
    let nested_on_full: Vec<Vec<f64>> = if coarse.is_some() { vec![nested] } else { Vec::new() };
    let refined_all: Vec<(f64, Vec<f64>)> = {
        // The nested model's refinement beside the screened starts' stages.
        let ((mut found, staged_count), (nested, nested_count)) =
            rayon::join(|| counted(|c| staged(&screened, TERM_CONTINUED, c)), || counted(|c| run(&table, &nested_on_full, long, true, c)));
        *evaluations.borrow_mut() += staged_count + nested_count;
        found.extend(nested);
        found.sort_by(|a, b| a.0.total_cmp(&b.0));
        found
    };
    let (term_nlml, term_packed) = refined_all.into_iter().next().ok_or(EvidenceError::NoValidSetting(LikelihoodSearch::CbdEvidence))?;
    let term_theta = Theta::unpack(&term_packed, n);
    let mut with_term = term_theta.to_user(&table.joint.forms, norm);
    let mut at_bounds = Vec::new();
    for d in 0..n {
        let v = term_packed[n + 3 + d];
        if v <= lower[n + 3 + d] + AT_BOUND || v >= upper[n + 3 + d] - AT_BOUND {
            let which = if v <= lower[n + 3 + d] + AT_BOUND { "lower" } else { "upper" };
            at_bounds.push(format!("joint {} width at its {which} bound", d + 1));
        }
    }
    if term_packed[2 * n + 3] >= flat - AT_BOUND {
        // Flat: the task factor's width ran to its upper bound, the factor is 1 in the blob.
        if let Some(c) = with_term.configuration.as_mut() {
            c.task_width = None;
        }
        at_bounds.push("task width at its upper bound (flat)".into());
    }
    let in_data_units = |nlml: f64| -nlml - ((used.len() * table.m) as f64) * norm.task_scale.ln();
    let (plain_log_evidence, with_term_log_evidence) = (in_data_units(plain_nlml), in_data_units(term_nlml));
    let added_hyperparameters = n + 2;
    let margin = 0.5 * (table.dim() as f64).ln() * added_hyperparameters as f64;
    Ok(ConfigurationEvidence {
        chosen: with_term_log_evidence - plain_log_evidence > margin,
        not_used: None,
        plain_log_evidence,
        with_term_log_evidence,
        margin,
        added_hyperparameters,
        rows: used.len(),
        with_term,
        at_bounds,
        evaluations: evaluations.into_inner(),
        seconds: start.elapsed().as_secs_f64(),
    })
}

/// The box with the term: the plain model's, then per joint K̃_Q's the joint kernel's bounds, a_C
/// the task width's (its upper bound 1e3 internal: flat) and γ_C γ_W's.
fn configuration_bounds(scales: &DataScales, table: &PairTable) -> (Vec<f64>, Vec<f64>) {
    let n = table.n;
    let (lo, hi) = scales.bounds(table);
    let mut lower = lo[..n + 3].to_vec();
    let mut upper = hi[..n + 3].to_vec();
    lower.extend_from_slice(&lo[..n]);
    upper.extend_from_slice(&hi[..n]);
    lower.extend([lo[n + 1], lo[n + 2], lo[n + 3]]);
    upper.extend([hi[n + 1], hi[n + 2], hi[n + 3]]);
    (lower, upper)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::simulate::{configurations, rr, Sampling};
    use faer::linalg::solvers::Solve;
    use faer::Mat;

    fn theta(flat: bool) -> Theta {
        Theta {
            log_widths: vec![0.3f64.ln(), 1.7f64.ln()],
            log_gamma_v: -3.0,
            log_a: 0.2,
            log_gamma_w: -4.0,
            log_sigma: -4.0,
            config: Some(ConfigTheta { log_widths: vec![2.0f64.ln(), 0.5f64.ln()], log_a: if flat { 7.0 } else { -0.3 }, log_gamma: -4.5 }),
        }
    }

    /// The value against a dense formula written out here (K_lin + γ_C exp(Σ c_d (cos Δ_d − 1))
    /// exp(−|Δk0|²/2a_C²) I + σ² I, Cholesky), and the gradient against central differences, with a
    /// finite and a (nearly) flat task factor.
    #[test]
    fn the_terms_evidence_is_the_dense_formula_and_its_gradient_is_exact() {
        let data = rr::RealRr::default().measure(&configurations(Sampling::Uniform { count: 20, seed: 3 }, 2));
        let norm = data.normalisation();
        let nominal = rr::nominal();
        let table = PairTable::new(&nominal, &data, &norm);
        for flat in [false, true] {
            let t = theta(flat);
            let (m, count) = (2, data.len());
            let kin: Vec<_> = (0..count).map(|i| crate::nominal::row_kinematics(&nominal, data.joints(i), i).normalised(&norm)).collect();
            let (gv, gw, gc) = (t.log_gamma_v.exp(), t.log_gamma_w.exp(), t.config.as_ref().unwrap().log_gamma.exp());
            let c: Vec<f64> = t.config.as_ref().unwrap().log_widths.iter().map(|l| l.exp()).collect();
            let b: Vec<f64> = t.log_widths.iter().map(|l| l.exp()).collect();
            let (a, ac) = (t.log_a.exp(), t.config.as_ref().unwrap().log_a.exp());
            let mut k = Mat::<f64>::zeros(count * m, count * m);
            for i in 0..count {
                for j in 0..count {
                    let (qi, qj) = (data.joints(i), data.joints(j));
                    let kq = |w: &[f64]| (0..2).map(|d| w[d] * ((qi[d] - qj[d]).cos() - 1.0)).sum::<f64>().exp();
                    let d2: f64 = (0..m).map(|e| (kin[i].position[e] - kin[j].position[e]).powi(2)).sum();
                    let iso = gw * (-d2 / (2.0 * a * a)).exp() + gc * kq(&c) * (-d2 / (2.0 * ac * ac)).exp();
                    for x in 0..m {
                        for y in 0..m {
                            let jj: f64 = (0..2).map(|d| kin[i].jacobian[x][d] * kin[j].jacobian[y][d]).sum();
                            k[(i * m + x, j * m + y)] = gv * kq(&b) * jj
                                + if x == y { iso } else { 0.0 }
                                + if i == j && x == y { (2.0 * t.log_sigma).exp() } else { 0.0 };
                        }
                    }
                }
            }
            let llt = k.llt(faer::Side::Lower).unwrap();
            let r = Mat::from_fn(count * m, 1, |i, _| table.residual[i]);
            let alpha = llt.solve(&r);
            let logdet: f64 = 2.0 * (0..count * m).map(|i| llt.L()[(i, i)].ln()).sum::<f64>();
            let quad: f64 = (0..count * m).map(|i| r[(i, 0)] * alpha[(i, 0)]).sum();
            let dense = 0.5 * quad + 0.5 * logdet + 0.5 * (count * m) as f64 * (2.0 * std::f64::consts::PI).ln();
            let (value, _) = table.nlml_and_gradient(&t.pack()).unwrap();
            assert!((value - dense).abs() <= 1e-8 * dense.abs().max(1.0), "flat {flat}: {value} vs dense {dense}");
            super::super::search::assert_gradient_matches_central_differences(&table, &t.pack(), 1e-5);
        }
    }

    /// θ with the term packs and unpacks to itself, σ last.
    #[test]
    fn theta_with_the_term_round_trips() {
        let t = theta(false);
        let p = t.pack();
        assert_eq!(p.len(), 2 * 2 + 6);
        assert_eq!(*p.last().unwrap(), t.log_sigma);
        assert_eq!(Theta::unpack(&p, 2), t);
    }
}

#[cfg(test)]
mod choice_tests {
    use super::*;
    use crate::simulate::six_joint::{random_configurations, SixJointRobot};
    use cbd_runtime::internals::kinematics::forward_kinematics;

    /// Six-joint arm measured on its nominal chain plus a translation that depends on the
    /// configuration (0.5 mm along x times sin(2 q1 + q4) cos q6; positions in mm) and 0.02 mm noise: the term is
    /// chosen, by more than its margin. Without the translation (noise only) it is not.
    #[test]
    fn the_term_is_chosen_exactly_where_the_residual_needs_it() {
        let robot = SixJointRobot::ur5_like(3);
        let joints = random_configurations(150, 4);
        let mut state = 0x2545f4914f6cdd1du64;
        let mut gauss = || {
            let mut u = || {
                state ^= state << 13;
                state ^= state >> 7;
                state ^= state << 17;
                (state >> 11) as f64 / (1u64 << 53) as f64
            };
            let (a, b) = (u().max(1e-300), u());
            (-2.0 * a.ln()).sqrt() * (2.0 * std::f64::consts::PI * b).cos()
        };
        let measure = |planted: f64, gauss: &mut dyn FnMut() -> f64| {
            let mut data = Measurements::new(6, 3);
            for q in joints.chunks_exact(6) {
                let k = forward_kinematics(&robot.nominal, q);
                let shift = planted * (2.0 * q[0] + q[3]).sin() * q[5].cos();
                let y = [k.position[0] + shift + 0.02 * gauss(), k.position[1] + 0.02 * gauss(), k.position[2] + 0.02 * gauss()];
                data.push(q, &y);
            }
            data
        };
        let options = EvidenceOptions::default();
        for (planted, expect) in [(0.5, true), (0.0, false)] {
            let data = measure(planted, &mut gauss);
            let norm = data.normalisation();
            let plain = crate::evidence::choose_cbd_hyperparameters(&robot.nominal, &data, &norm, &options).unwrap();
            let rows = EvidenceRows::new(&data, options.max_unknowns, options.coarse_unknowns);
            let found = search_configuration_term(&robot.nominal, &data, &rows, &norm, &options, &plain.hyperparameters).unwrap();
            errln!("planted {planted}: {}", found.describe());
            assert_eq!(found.chosen, expect, "{}", found.describe());
        }
    }
}

//! `cbd plan --check N --blob B` (issue 50 item 5): the N poses that make `cbd check` most
//! sensitive to the changes it names (`evaluation::check::name`), and for each kind of change the
//! smallest one the check detects at α with 90 % power.
//!
//! A change of size s along an effect column f (the prediction's derivative at the chosen poses)
//! moves the fresh residual's mean by s f; the check's statistic rᵀC⁻¹r is then noncentral χ² on
//! the check's dof with noncentrality λ = s² fᵀC⁻¹f (C: the check's covariance at those poses,
//! `covariance::fresh_covariance`). The detectable size is s = √(λ₉₀ / fᵀC⁻¹f), λ₉₀ the
//! noncentrality at which P(χ'² > the χ² quantile at 1 − α) = 0.9; a shift (three columns) is
//! taken in its least visible direction (the smallest eigenvalue of FᵀC⁻¹F).
//!
//! The poses are chosen greedily from candidates sampled as `cbd plan` samples them (uniform within
//! the joint limits, at least 1° from a singular configuration), each step the candidate that most
//! lowers Σ_k 1/v_k, v_k the kind's information fᵀC⁻¹f summed over the chosen poses (C's per-pose
//! blocks) over its mean per candidate pose: the sum of the squared detectable sizes, each in units
//! of its size at one average random pose. The sizes reported are computed with the full C.

use crate::data::Measurements;
use crate::evaluation::check::covariance::{fresh_covariance, spd_inverse as inverse};
use crate::evaluation::check::name::{candidate_columns, candidates, projected_precision, tangent_columns, Candidate};
use crate::evaluation::check::statistic::chi2_survival;
use crate::plan::candidates as cand;
use cbd_protocol::{Model, NominalModel};
use faer::{Mat, Side};

/// The power the detectable sizes are stated at.
pub const POWER: f64 = 0.9;
/// Random pose sets whose detectable sizes' median is the random baseline.
pub const RANDOM_SETS: usize = 5;
/// The candidates the greedy choice considers (the first of those sampled), with C over all of them.
pub const GREEDY_POOL: usize = 600;

/// P(χ'²(k, λ) > x): the Poisson(λ/2) mixture of central χ²(k + 2j) survivals.
pub fn noncentral_chi2_survival(x: f64, k: f64, lambda: f64) -> f64 {
    if lambda <= 0.0 {
        return chi2_survival(x, k);
    }
    let h = 0.5 * lambda;
    let last = (h + 12.0 * h.sqrt() + 40.0).ceil() as usize;
    let mut total = 0.0;
    for j in 0..=last {
        let ln_w = -h + j as f64 * h.ln() - crate::diagnose::f_test::ln_gamma(j as f64 + 1.0);
        total += ln_w.exp() * chi2_survival(x, k + 2.0 * j as f64);
    }
    total.clamp(0.0, 1.0)
}

/// The χ² quantile at 1 − α on k degrees of freedom: P(χ²(k) > x) = α, by bisection.
pub fn chi2_critical(alpha: f64, k: f64) -> f64 {
    let mut hi = k + 10.0 * (2.0 * k).sqrt() + 50.0;
    while chi2_survival(hi, k) > alpha {
        hi *= 2.0;
    }
    let mut lo = 0.0;
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if chi2_survival(mid, k) > alpha {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

/// The noncentrality at which the χ² test on k dof at level α has power `power`.
pub fn detectable_noncentrality(alpha: f64, k: f64, power: f64) -> f64 {
    let x = chi2_critical(alpha, k);
    let mut hi = 10.0 + k;
    while noncentral_chi2_survival(x, k, hi) < power {
        hi *= 2.0;
    }
    let mut lo = 0.0;
    for _ in 0..100 {
        let mid = 0.5 * (lo + hi);
        if noncentral_chi2_survival(x, k, mid) < power {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

/// One kind of change and the smallest of it the check detects with the random and planned poses.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct DetectableSize {
    /// The `--effect` spelling: `joint_zero:joint=2`.
    pub effect: String,
    /// `rad`, the length unit, or `` (a ratio: encoder scale, length scale − 1).
    pub unit: String,
    /// The median over [`RANDOM_SETS`] sets of N random candidate poses.
    pub random: f64,
    pub planned: f64,
}

/// What [`plan_check`] found.
#[derive(Debug, Clone, serde::Serialize)]
pub struct CheckPlan {
    /// The planned poses, model joints and the controller's values (row-major, model units).
    pub poses: Vec<f64>,
    pub controller: Vec<f64>,
    pub sizes: Vec<DetectableSize>,
    /// Kinds the measured point does not see (no detectable size): spelling.
    pub invisible: Vec<String>,
    /// Kinds the registered frame takes up (with `register`; no size detects them): spelling.
    pub framed: Vec<String>,
    pub dof: usize,
    pub alpha: f64,
    pub power: f64,
    /// The noncentrality detected with [`POWER`].
    pub noncentrality: f64,
    pub candidates: usize,
    pub rejected_singular: usize,
    pub seconds: f64,
}

/// Why the check's poses could not be planned (the CLI names the files).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PlanCheckError {
    #[error("the changes the check names are those of a DH chain measured in 3-D at one tool point")]
    NotDhChain,
    #[error("{count} poses asked for, but only {available} candidates are at least 1° from a singular configuration; raise --candidates")]
    TooFewCandidates { count: usize, available: usize },
    #[error("the check's covariance at the candidate poses is not positive definite")]
    NotPositiveDefinite,
    #[error("{count} poses for a check with the frame registered: it needs at least 3 (the frame takes 6 of their degrees of freedom)")]
    TooFewForFrame { count: usize },
}

/// What plan_check needs.
pub struct CheckPlanInput<'a> {
    pub model: &'a Model<'a>,
    /// The blob's chain is DH-calibrated (its parameters' uncertainty is part of C), as `cbd check` decides.
    pub geometry: bool,
    pub limits: &'a [[f64; 2]],
    /// The controller's values → the model's joints, when they differ.
    pub to_model: Option<&'a dyn Fn(&[f64]) -> Vec<f64>>,
    pub count: usize,
    pub candidates: usize,
    pub seed: u64,
    pub alpha: f64,
    /// The check registers the fresh rows' frame (`cbd check --register`): its tangent is projected
    /// out of every size (6 degrees of freedom fewer) and `base_shift` is not offered.
    pub register: bool,
    /// The data's length unit (the unit of a length's size).
    pub unit: &'a str,
}

fn rows(n: usize, joints: Vec<f64>) -> Measurements {
    let mut m = Measurements::with_points(n, 3, 1);
    m.positions = vec![0.0; joints.len() / n * 3];
    m.joints = joints;
    m
}

/// The smallest eigenvalue of a symmetric matrix.
fn smallest_eigenvalue(a: &Mat<f64>) -> f64 {
    if a.nrows() == 1 {
        return a[(0, 0)];
    }
    a.self_adjoint_eigenvalues(Side::Lower).map_or(0.0, |ev| ev.iter().cloned().fold(f64::INFINITY, f64::min))
}

/// FᵀWF for the columns `f` (each over `dim` rows) and a symmetric W.
fn information(w: &Mat<f64>, f: &[Vec<f64>]) -> Mat<f64> {
    let dim = w.nrows();
    let fm = Mat::from_fn(dim, f.len(), |i, k| f[k][i]);
    fm.transpose() * (w * &fm)
}

/// The unit of a kind's size.
fn unit_of(c: Candidate, length: &str) -> String {
    match c {
        Candidate::JointZero(_) | Candidate::LinkTwist(_) => "rad".into(),
        Candidate::LinkLength(_) | Candidate::BaseShift | Candidate::ToolShift => length.into(),
        Candidate::EncoderScale(_) | Candidate::LengthScale => String::new(),
    }
}

/// Each kind's smallest detectable size at the poses `joints` (model joints, row-major), with the
/// full C there; `None` for a kind with no information.
fn sizes_at(input: &CheckPlanInput, kinds: &[Candidate], joints: &[f64], lambda: f64) -> Result<Vec<f64>, PlanCheckError> {
    let n = input.model.n_joints();
    let fresh = rows(n, joints.to_vec());
    let c = fresh_covariance(input.model, &fresh, input.geometry).ok_or(PlanCheckError::NotPositiveDefinite)?;
    let free = inverse(&c).ok_or(PlanCheckError::NotPositiveDefinite)?;
    // The registered check's statistic is on the part of r the frame's tangent T does not explain:
    // its information is Fᵀ P F (the tangent at the nominal positions: the frame moves them, the
    // millimetres between k0 and k1 do not matter).
    let projected = if input.register {
        let norm = &input.model.normalisation;
        let positions: Vec<f64> =
            crate::nominal::positions(&input.model.nominal, joints, 3).iter().map(|v| norm.length_to_internal(*v)).collect();
        let t = crate::evaluation::check::register::tangent(&positions);
        Some(projected_precision(&free, &tangent_columns(Some(&t))).ok_or(PlanCheckError::NotPositiveDefinite)?)
    } else {
        None
    };
    let cinv = projected.as_ref().unwrap_or(&free);
    let columns = candidate_columns(input.model, &fresh, kinds);
    Ok(columns
        .iter()
        .map(|f| {
            let info = smallest_eigenvalue(&information(cinv, f));
            // A kind the registered frame takes up (joint 1's zero turns the arm about the base's
            // axis, as the frame does): no size detects it.
            if input.register && !(info > 1e-9 * smallest_eigenvalue(&information(&free, f))) {
                return f64::INFINITY;
            }
            // The columns are per unit of the parameter (a length in the data's unit, an angle in
            // radians): s is in those units.
            (lambda / info).sqrt()
        })
        .collect())
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// Plans the check's poses: see the module's documentation.
pub fn plan_check(input: &CheckPlanInput) -> Result<CheckPlan, PlanCheckError> {
    let start = std::time::Instant::now();
    let model = input.model;
    let NominalModel::DhChain(_) = &model.nominal else { return Err(PlanCheckError::NotDhChain) };
    if model.task_dim() != 3 || model.nominal.tool_point_count() > 1 {
        return Err(PlanCheckError::NotDhChain);
    }
    if input.register && 3 * input.count <= crate::evaluation::check::register::FRAME_DOF {
        return Err(PlanCheckError::TooFewForFrame { count: input.count });
    }
    let n = model.n_joints();
    let to_model = |c: &[f64]| -> Vec<f64> {
        match input.to_model {
            Some(f) => c.chunks_exact(n).flat_map(f).collect(),
            None => c.to_vec(),
        }
    };
    let nominal = &model.nominal;
    let reach = cand::reach(nominal, &to_model(&cand::uniform_within(input.limits, 500, input.seed.wrapping_add(2))));
    let pool = cand::uniform_within(input.limits, input.candidates, input.seed);
    let pool_model = to_model(&pool);
    let (mut joints, mut controller, mut rejected_singular) = (Vec::new(), Vec::new(), 0);
    for (c, q) in pool.chunks_exact(n).zip(pool_model.chunks_exact(n)) {
        if cand::singular_distance(nominal, q, reach) >= cand::SINGULAR_MARGIN && cand::within_limits(c, input.limits) {
            joints.extend_from_slice(q);
            controller.extend_from_slice(c);
        } else {
            rejected_singular += 1;
        }
    }
    let available = joints.len() / n;
    if available < input.count.max(1) * RANDOM_SETS.min(2) {
        return Err(PlanCheckError::TooFewCandidates { count: input.count, available });
    }
    let kinds_all = candidates(n, input.register);
    let pool_rows = rows(n, joints.clone());
    let columns = candidate_columns(model, &pool_rows, &kinds_all);

    // C's per-pose 3×3 blocks at every candidate, inverted (batches: C over a batch is its square).
    let mut block_inv: Vec<Mat<f64>> = Vec::with_capacity(available);
    for batch in joints.chunks(200 * n) {
        let c = fresh_covariance(model, &rows(n, batch.to_vec()), input.geometry).ok_or(PlanCheckError::NotPositiveDefinite)?;
        for p in 0..batch.len() / n {
            let b = Mat::from_fn(3, 3, |i, j| c[(3 * p + i, 3 * p + j)]);
            block_inv.push(inverse(&b).ok_or(PlanCheckError::NotPositiveDefinite)?);
        }
    }
    // Each kind's information at each candidate: FₚᵀBₚ⁻¹Fₚ (1×1, or 3×3 for a shift).
    let info: Vec<Vec<Mat<f64>>> = columns
        .iter()
        .map(|f| {
            (0..available)
                .map(|p| {
                    let fp: Vec<Vec<f64>> = f.iter().map(|col| col[3 * p..3 * p + 3].to_vec()).collect();
                    information(&block_inv[p], &fp)
                })
                .collect()
        })
        .collect();
    // A kind the measured point does not see: its mean information per pose below 1e-12 of what a
    // unit change of the same sort gives at the arm's reach (an angle or ratio) or at itself (a length).
    let scale = model.normalisation.length_to_internal(1.0);
    let sigma2 = {
        let b = &block_inv[0];
        3.0 / (b[(0, 0)] + b[(1, 1)] + b[(2, 2)])
    };
    let mut kinds = Vec::new();

    let mut norms = Vec::new();
    let mut invisible = Vec::new();
    for (k, kind) in kinds_all.iter().enumerate() {
        let w = info[k][0].nrows();
        let mean = Mat::from_fn(w, w, |i, j| info[k].iter().map(|a| a[(i, j)]).sum::<f64>() / available as f64);
        let natural = match unit_of(*kind, "l").as_str() {
            "l" => scale * scale,
            _ => (scale * reach).powi(2),
        } / sigma2;
        let level = smallest_eigenvalue(&mean);
        if level > 1e-12 * natural {
            kinds.push(*kind);

            norms.push(level);
        } else {
            invisible.push(kind.spelling());
        }
    }

    // Greedy over the first GREEDY_POOL candidates, with the full C there: each step the candidate
    // that most lowers Σ_k 1/v_k, the information of S ∪ {p} by the Schur complement of C_S.
    let g = available.min(GREEDY_POOL).max(input.count);
    let cfull = fresh_covariance(model, &rows(n, joints[..g * n].to_vec()), input.geometry).ok_or(PlanCheckError::NotPositiveDefinite)?;
    let fk: Vec<&Vec<Vec<f64>>> =
        kinds.iter().map(|kind| &columns[kinds_all.iter().position(|c| c == kind).expect("a kind of the list")]).collect();
    let mut info_s: Vec<Mat<f64>> = fk.iter().map(|f| Mat::zeros(f.len(), f.len())).collect();
    let mut chosen: Vec<usize> = Vec::with_capacity(input.count);
    let mut taken = vec![false; g];
    for _ in 0..input.count {
        let rs: Vec<usize> = chosen.iter().flat_map(|&p| 3 * p..3 * p + 3).collect();
        let s = rs.len();
        let w = if s > 0 {
            inverse(&Mat::from_fn(s, s, |i, j| cfull[(rs[i], rs[j])])).ok_or(PlanCheckError::NotPositiveDefinite)?
        } else {
            Mat::zeros(0, 0)
        };
        let gk: Vec<Mat<f64>> = fk.iter().map(|f| &w * Mat::from_fn(s, f.len(), |i, c| f[c][rs[i]])).collect();
        let gain = |p: usize| -> Option<Vec<Mat<f64>>> {
            let c = Mat::from_fn(s, 3, |i, j| cfull[(rs[i], 3 * p + j)]);
            let b = Mat::from_fn(3, 3, |i, j| cfull[(3 * p + i, 3 * p + j)]);
            let schur = &b - c.transpose() * (&w * &c);
            let sinv = inverse(&schur)?;
            Some(
                fk.iter()
                    .zip(&gk)
                    .map(|(f, gk)| {
                        let u = Mat::from_fn(3, f.len(), |i, cc| f[cc][3 * p + i]) - c.transpose() * gk;
                        u.transpose() * (&sinv * &u)
                    })
                    .collect(),
            )
        };
        let mut best: Option<(usize, f64)> = None;
        for p in (0..g).filter(|&p| !taken[p]) {
            let Some(add) = gain(p) else { continue };
            let cost: f64 = add.iter().enumerate().map(|(k, a)| 1.0 / (smallest_eigenvalue(&(&info_s[k] + a)) / norms[k] + 1e-3)).sum();
            if best.is_none_or(|(_, b)| cost < b) {
                best = Some((p, cost));
            }
        }
        let (p, _) = best.ok_or(PlanCheckError::NotPositiveDefinite)?;
        let add = gain(p).ok_or(PlanCheckError::NotPositiveDefinite)?;
        for (a, d) in info_s.iter_mut().zip(&add) {
            *a += d;
        }
        taken[p] = true;
        chosen.push(p);
    }

    let k = 3 * input.count - if input.register { crate::evaluation::check::register::FRAME_DOF } else { 0 };
    let lambda = detectable_noncentrality(input.alpha, k as f64, POWER);
    let pick = |set: &[usize]| -> Vec<f64> { set.iter().flat_map(|&p| joints[p * n..(p + 1) * n].iter().copied()).collect() };
    let planned = sizes_at(input, &kinds, &pick(&chosen), lambda)?;
    // Random: consecutive sets of N of the (uniform) candidates.
    let sets = RANDOM_SETS.min(available / input.count).max(1);
    let mut random: Vec<Vec<f64>> = Vec::new();
    for s in 0..sets {
        let set: Vec<usize> = (s * input.count..(s + 1) * input.count).collect();
        random.push(sizes_at(input, &kinds, &pick(&set), lambda)?);
    }
    let mut framed = Vec::new();
    let mut sizes = Vec::new();
    for (i, kind) in kinds.iter().enumerate() {
        if planned[i].is_infinite() {
            framed.push(kind.spelling());
            continue;
        }
        let random = median(random.iter().map(|r| r[i]).collect());
        sizes.push(DetectableSize { effect: kind.spelling(), unit: unit_of(*kind, input.unit), random, planned: planned[i] });
    }
    Ok(CheckPlan {
        poses: pick(&chosen),
        controller: chosen.iter().flat_map(|&p| controller[p * n..(p + 1) * n].iter().copied()).collect(),
        sizes,
        invisible,
        framed,
        dof: k,
        alpha: input.alpha,
        power: POWER,
        noncentrality: lambda,
        candidates: available,
        rejected_singular,
        seconds: start.elapsed().as_secs_f64(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// One degree of freedom: the test is |z| > z_{α/2}, detected with power 0.9 at
    /// √λ = z_{α/2} + z_{0.9}: λ = (1.95996 + 1.28155)² = 10.507 at α = 0.05.
    #[test]
    fn the_detectable_noncentrality_matches_the_normal_case() {
        assert!((chi2_critical(0.05, 1.0) - 3.841459).abs() < 1e-5);
        let l = detectable_noncentrality(0.05, 1.0, 0.9);
        assert!((l - 10.5074).abs() < 2e-3, "{l}");
        // At λ = 0 the power is α; it grows with λ.
        let x = chi2_critical(0.01, 60.0);
        assert!((noncentral_chi2_survival(x, 60.0, 0.0) - 0.01).abs() < 1e-9);
        assert!(noncentral_chi2_survival(x, 60.0, 10.0) < noncentral_chi2_survival(x, 60.0, 20.0));
        // 60 dof, α = 0.01: P(χ'² > x) = 0.9; the mean of χ'² is k + λ.
        let l = detectable_noncentrality(0.01, 60.0, 0.9);
        assert!((noncentral_chi2_survival(x, 60.0, l) - 0.9).abs() < 1e-6 && l > 30.0 && l < 60.0, "{l}");
    }
}

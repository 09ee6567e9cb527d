//! L-BFGS (argmin) on the negative log evidence over θ in log space, inside bounds.

use argmin::core::{CostFunction, Executor, Gradient, State};
use argmin::solver::linesearch::{condition::ArmijoCondition, BacktrackingLineSearch};
use argmin::solver::quasinewton::LBFGS;
use std::cell::RefCell;

/// A negative log evidence over θ's packed form: the kernel form's ([`super::PairTable`]) or the
/// weight space's ([`super::weight_space::WeightSpaceTable`]).
pub(crate) trait Criterion {
    /// Observations (N m): the per-unknown scale of values, gradients and tolerances.
    fn observations(&self) -> usize;
    /// Value and gradient; `None` where the covariance is not positive definite.
    fn nlml_and_gradient(&self, packed: &[f64]) -> Option<(f64, Vec<f64>)>;
    /// The value alone, and what [`Criterion::gradient_from`] at the same point reuses: a line
    /// search's trial points need no gradient, and most are rejected (the kernel form then skips
    /// K⁻¹, two thirds of an evaluation's flops). Default: the gradient too, carried along.
    fn nlml(&self, packed: &[f64]) -> Option<(f64, Partial)> {
        self.nlml_and_gradient(packed).map(|(value, gradient)| (value, Box::new(gradient) as Partial))
    }
    /// The gradient at the point [`Criterion::nlml`] left `partial` for (the same bits as
    /// [`Criterion::nlml_and_gradient`]'s).
    fn gradient_from(&self, packed: &[f64], partial: Partial) -> Option<Vec<f64>> {
        match partial.downcast::<Vec<f64>>() {
            Ok(gradient) => Some(*gradient),
            Err(_) => self.nlml_and_gradient(packed).map(|(_, gradient)| gradient),
        }
    }
    /// Where L-BFGS stops, per unknown: (change of the value, gradient). Default TOLERANCE for
    /// both, the kernel form's own rounding.
    fn tolerances(&self) -> (f64, f64) {
        (TOLERANCE, TOLERANCE)
    }
}

/// What a [`Criterion::nlml`] evaluation leaves for the gradient at the same point.
pub(crate) type Partial = Box<dyn std::any::Any>;

/// The objective argmin sees: nlml plus a quadratic wall outside the bounds. The last point is
/// cached: the line search asks for its value, L-BFGS for the accepted point's gradient next, which
/// is computed then from what the value left.
struct Objective<'a> {
    table: &'a dyn Criterion,
    lower: Vec<f64>,
    upper: Vec<f64>,
    wall: f64,
    cache: RefCell<Option<Evaluated>>,
    /// Likelihood evaluations, counted across every run that shares it.
    evaluations: &'a RefCell<usize>,
}

/// Where L-BFGS stops: a change of the objective, or a gradient, below 1e-4 nats per unknown. Near
/// the optimum of nearly singular kernels the evaluation's own rounding is about that large (on the
/// noisy RR grid, N m = 512: ±1 nat between evaluations at the same θ to 3 digits), and a tighter
/// tolerance only chases it (measured at 1e-6: 27 % more evaluations, test error within 0.4 %).
const TOLERANCE: f64 = 1e-4;

/// Value returned where K is not positive definite: finite, so that the line search backtracks.
const INFEASIBLE: f64 = 1e300;

/// The objective at one point: its value, and its gradient once asked for (until then, what the
/// value left for it).
struct Evaluated {
    at: Vec<f64>,
    value: f64,
    gradient: Option<Vec<f64>>,
    partial: Option<Partial>,
}

impl Objective<'_> {
    fn clamped(&self, p: &[f64]) -> Vec<f64> {
        p.iter().zip(self.lower.iter().zip(&self.upper)).map(|(v, (lo, hi))| v.clamp(*lo, *hi)).collect()
    }

    /// Per unknown: a first L-BFGS step of −g is then of order one in log space, and the
    /// tolerances scale with the evaluation's own rounding (which grows with N m).
    fn per_unknown(&self) -> f64 {
        1.0 / self.table.observations() as f64
    }

    /// How far `x`, coordinate `k` of a point, lies outside the box (signed: above the upper bound
    /// positive, below the lower negative; 0 inside): the wall's distance.
    fn over(&self, k: usize, x: f64) -> f64 {
        (x - self.upper[k]).max(0.0) - (self.lower[k] - x).max(0.0)
    }

    /// The objective's value at `p`, evaluated (and cached) unless `p` is the cached point.
    fn value(&self, p: &[f64]) -> f64 {
        if let Some(e) = self.cache.borrow().as_ref().filter(|e| e.at.as_slice() == p) {
            return e.value;
        }
        // A non-finite trial point (an L-BFGS update from a vanishing step) is rejected, never evaluated.
        if p.iter().any(|v| !v.is_finite()) {
            *self.cache.borrow_mut() =
                Some(Evaluated { at: p.to_vec(), value: INFEASIBLE, gradient: Some(vec![0.0; p.len()]), partial: None });
            return INFEASIBLE;
        }
        *self.evaluations.borrow_mut() += 1;
        let (mut value, partial) = match self.table.nlml(&self.clamped(p)) {
            Some((v, partial)) => (v * self.per_unknown(), Some(partial)),
            None => (INFEASIBLE, None),
        };
        if value < INFEASIBLE {
            for (k, x) in p.iter().enumerate() {
                let over = self.over(k, *x);
                if over != 0.0 {
                    value += self.wall * over * over;
                }
            }
        }
        let gradient = partial.is_none().then(|| vec![0.0; p.len()]);
        *self.cache.borrow_mut() = Some(Evaluated { at: p.to_vec(), value, gradient, partial });
        value
    }

    /// Value and gradient at `p`.
    fn both(&self, p: &[f64]) -> (f64, Vec<f64>) {
        let value = self.value(p);
        let mut cache = self.cache.borrow_mut();
        let Some(e) = cache.as_mut() else { return (INFEASIBLE, vec![0.0; p.len()]) };
        if e.gradient.is_none() {
            let partial = e.partial.take();
            let from_table = partial.and_then(|partial| self.table.gradient_from(&self.clamped(p), partial));
            let per_unknown = self.per_unknown();
            let mut g: Vec<f64> = match from_table {
                Some(g) => g.iter().map(|x| x * per_unknown).collect(),
                None => vec![0.0; p.len()],
            };
            if value < INFEASIBLE {
                for (k, x) in p.iter().enumerate() {
                    let over = self.over(k, *x);
                    if over != 0.0 {
                        g[k] = 2.0 * self.wall * over;
                    }
                }
            }
            e.gradient = Some(g);
        }
        (value, e.gradient.clone().unwrap_or_else(|| vec![0.0; p.len()]))
    }
}

impl CostFunction for &Objective<'_> {
    type Param = Vec<f64>;
    type Output = f64;
    fn cost(&self, p: &Vec<f64>) -> Result<f64, argmin::core::Error> {
        Ok(self.value(p))
    }
}

impl Gradient for &Objective<'_> {
    type Param = Vec<f64>;
    type Gradient = Vec<f64>;
    fn gradient(&self, p: &Vec<f64>) -> Result<Vec<f64>, argmin::core::Error> {
        Ok(self.both(p).1)
    }
}

/// L-BFGS from `init` (clamped into the box): the best (nlml, θ) found, None if `init` is infeasible.
pub(crate) fn minimise(
    table: &dyn Criterion,
    lower: &[f64],
    upper: &[f64],
    init: &[f64],
    max_iterations: u64,
    evaluations: &RefCell<usize>,
) -> Option<(f64, Vec<f64>)> {
    let clamp = |p: &[f64]| -> Vec<f64> { p.iter().zip(lower.iter().zip(upper)).map(|(v, (lo, hi))| v.clamp(*lo, *hi)).collect() };
    let objective = Objective { table, lower: lower.to_vec(), upper: upper.to_vec(), wall: 10.0, cache: RefCell::new(None), evaluations };
    let mut init = clamp(init);
    // A start where K is not positive definite to working precision (a σ that was fine on fewer
    // rows) moves up in σ until it is.
    let sigma_at = init.len() - 1;
    let mut feasible = objective.value(&init) < INFEASIBLE;
    for _ in 0..12 {
        if feasible || init[sigma_at] >= upper[sigma_at] {
            break;
        }
        init[sigma_at] = (init[sigma_at] + 0.5 * 10f64.ln()).min(upper[sigma_at]);
        feasible = objective.value(&init) < INFEASIBLE;
    }
    let mut param = init.clone();
    if feasible {
        let condition = ArmijoCondition::new(1e-4).ok()?;
        // Backtrack by 1/5 (argmin's default 0.9 spends many evaluations on a first step of |g|).
        let linesearch = BacktrackingLineSearch::new(condition).rho(0.2).ok()?;
        let (cost_tolerance, gradient_tolerance) = table.tolerances();
        let solver =
            LBFGS::new(linesearch, 8).with_tolerance_grad(gradient_tolerance).and_then(|s| s.with_tolerance_cost(cost_tolerance)).ok()?;
        // A failed line search still leaves the start usable.
        if let Ok(result) = Executor::new(&objective, solver).configure(|s| s.param(init.clone()).max_iters(max_iterations)).run() {
            if let Some(p) = result.state().get_best_param() {
                param = clamp(p);
            }
        }
    }
    if !feasible {
        return None;
    }
    // The last point L-BFGS evaluated is usually the best one: the cache answers.
    let value = objective.value(&param);
    (value < INFEASIBLE).then_some((value * table.observations() as f64, param))
}

/// `found` (total nlml, θ with σ last), or a better optimum above its σ: as σ → 0 the evidence
/// flattens (σ² I vanishes against K_lin, and so does the gradient in log σ), and L-BFGS stops on that
/// plateau by its gradient rule while a higher evidence lies at the noise (the RR torus grid of 6 × 6
/// poses with noise 1e-4: σ stopped at 8.6e-7, 8 nats below σ ≈ 1e-4, and `cbd check` then rejected
/// fresh poses of the same arm). The value alone at σ raised by decades to its bound, the other
/// components fixed; where one beats `found` by more than [`PLATEAU_GAIN`], L-BFGS from there, kept
/// if it ends better. On a true optimum every probe is worse and `found` is returned as it was.
pub(crate) fn off_the_noise_plateau(
    table: &dyn Criterion,
    lower: &[f64],
    upper: &[f64],
    found: (f64, Vec<f64>),
    max_iterations: u64,
    evaluations: &RefCell<usize>,
) -> (f64, Vec<f64>) {
    let s = found.1.len() - 1;
    let mut best: Option<(f64, Vec<f64>)> = None;
    let mut p = found.1.clone();
    loop {
        p[s] += std::f64::consts::LN_10;
        if p[s] > upper[s] {
            break;
        }
        *evaluations.borrow_mut() += 1;
        let Some((value, _)) = table.nlml(&p) else { continue };
        if best.as_ref().map_or(true, |b| value < b.0) {
            best = Some((value, p.clone()));
        }
    }
    match best {
        Some((value, from)) if value < found.0 - PLATEAU_GAIN => match minimise(table, lower, upper, &from, max_iterations, evaluations) {
            Some(better) if better.0 < found.0 => better,
            _ => found,
        },
        _ => found,
    }
}

/// Nats a probe above σ must gain for [`off_the_noise_plateau`] to search from it (the restarts' gain).
const PLATEAU_GAIN: f64 = 0.5;

/// `search` from each of `starts` on the command's workers, the results in `starts`' order, their
/// likelihood evaluations added to `evaluations`. The searches share nothing else (each has its own
/// L-BFGS state and cache; the likelihoods' factorisations split in fixed pieces), so the results
/// are a serial loop's, bit for bit, on one worker or two; the starts of a search are what it spends
/// its time on, and one search keeps a second core only partly busy.
pub(crate) fn from_each<T: Sync, R: Send>(
    starts: &[T],
    evaluations: &RefCell<usize>,
    search: impl Fn(&T, &RefCell<usize>) -> R + Sync,
) -> Vec<R> {
    use rayon::prelude::*;
    let found: Vec<(R, usize)> = starts.par_iter().with_max_len(1).map(|start| counted(|evaluations| search(start, evaluations))).collect();
    *evaluations.borrow_mut() += found.iter().map(|(_, count)| count).sum::<usize>();
    found.into_iter().map(|(result, _)| result).collect()
}

/// `search`'s result and the likelihood evaluations it counted: a search run beside others (on
/// another worker) counts on its own, and the caller adds the counts.
pub(crate) fn counted<R>(search: impl FnOnce(&RefCell<usize>) -> R) -> (R, usize) {
    let evaluations = RefCell::new(0);
    let result = search(&evaluations);
    (result, evaluations.into_inner())
}

/// Test helper: `criterion`'s analytic gradient at `p` against central differences (step 1e-5 in each
/// log parameter), within `relative` of max(|difference quotient|, 1).
#[cfg(test)]
pub(crate) fn assert_gradient_matches_central_differences(criterion: &dyn Criterion, p: &[f64], relative: f64) {
    let (_, grad) = criterion.nlml_and_gradient(p).unwrap();
    for k in 0..p.len() {
        let h = 1e-5;
        let (mut up, mut down) = (p.to_vec(), p.to_vec());
        up[k] += h;
        down[k] -= h;
        let fd = (criterion.nlml_and_gradient(&up).unwrap().0 - criterion.nlml_and_gradient(&down).unwrap().0) / (2.0 * h);
        assert!((fd - grad[k]).abs() <= relative * fd.abs().max(1.0), "θ[{k}]: analytic {} vs finite differences {fd}", grad[k]);
    }
}

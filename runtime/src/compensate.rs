//! Compensation: the joint command q that puts the calibrated model's tool at a target,
//! k1(q) = target, by a fixed number of damped minimum-norm Gauss–Newton steps on the exact
//! Jacobian Dk1 (eq. 20 and [`crate::flow::query_derivatives`]) from a seed, typically the nominal
//! model's inverse kinematics ([`crate::inverse_kinematics`]). Fixed cost, no heap, no panic.

use crate::error::Error;
use crate::evaluate::{evaluate, evaluate_transported, Evaluation};
use crate::flow_maps::inverse_flow_start;
use crate::inverse_kinematics::fold::{fold_root, nominal_curvature, smallest_singular_pair};
use crate::inverse_kinematics::{bounded_step, conditioning, damped_min_norm_direction, matrices_of, padded_target};
use crate::load::Calibrator;
use cbd_protocol::{MAX_JOINTS as NJ, MAX_TASK_DIM as MT};
use nalgebra::{SMatrix, SVector};

/// Settings of [`Calibrator::compensate_with`]. Every field is a number the caller can see; none
/// makes the cost depend on the data.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CompensateOptions {
    /// Start from the inverse flows, k1⁻¹ ≈ φ ∘ k0⁻¹ ∘ ψ⁻¹ ([`Calibrator::inverse_flow_start`]),
    /// instead of the seed itself (the seed then picks the nominal inverse kinematics' branch).
    pub inverse_flow_start: bool,
    /// Gauss–Newton steps on the exact Jacobian Dk1, each after an evaluation with it.
    pub iterations: usize,
    /// Corrections of the inverse-flow start before the Gauss–Newton steps (defect correction):
    /// each evaluates k1 at the start (position only) and restarts the inverse flows from the
    /// target moved by the miss, y ← y + (target − k1(start)). Near a fold (the arm almost
    /// stretched) the nominal closed form inside it resolves the fold's square-root behaviour that
    /// slows Newton there. Ignored without `inverse_flow_start`.
    pub start_corrections: usize,
    /// Chord steps after those: each reuses the last exact Jacobian and needs only a position
    /// ([`Calibrator::evaluate_transported`]). Cost in all: `iterations` evaluations with the exact
    /// Jacobian, `chord_steps + 1` position-only evaluations, and the start.
    pub chord_steps: usize,
    /// Fold-aware exact steps: along the smallest singular pair (σ, u, v) of Dk1 the step is the
    /// nearer root of σ t + ½ a t² = uᵀ r instead of Newton's uᵀ r / σ, with a = uᵀ D²k0[v, v]
    /// the nominal model's curvature ([`crate::inverse_kinematics::fold`]; two evaluations of k0
    /// per step, no extra evaluation of k1).
    pub fold_steps: bool,
    /// Keep the inverse-flow start only when its residual beats the seed's (one more
    /// position-only evaluation, at the seed); otherwise the evaluations after the start's go to
    /// Gauss–Newton from the seed. Ignored without `inverse_flow_start`.
    pub start_guard: bool,
    /// Largest |k1(q) − target| (user units) counted as reached.
    pub tolerance: f64,
    /// Kernel support below which the command is flagged outside the calibrated region
    /// ([`Evaluation::is_extrapolating`]).
    pub extrapolation_threshold: f64,
    /// [`conditioning`] of Dk1 below which the command is flagged singular.
    pub singular_conditioning: f64,
}

/// Gauss–Newton steps of the nominal inverse kinematics inside [`Calibrator::inverse_flow_start`]
/// (on k0 alone: cheap beside one evaluation of k1).
pub const NOMINAL_ITERATIONS: usize = 8;

impl CompensateOptions {
    /// The inverse-flow start and four fold-aware Gauss–Newton steps (`fold_steps`), no guard,
    /// no chord steps. Four since issue 25: on RR models trained from noisy and noise-free data
    /// (tests/tests/cross_crate/expansion_fit.rs) three steps left 2.4 % of 1000 reachable targets in the folded-arm
    /// band (q2 near ±π, where the nominal inverse misses by ~0.4 rad) 1.5–14 × 1e-9 short; the
    /// fourth brings every one of them to ~1e-15 (quadratic convergence). Measured with three, over 2000 reachable targets per model
    /// (`steps_saved_by_the_inverse_flow_start` in tests/tests/cross_crate/compensate.rs): 100 % within 1e-9
    /// of the reach on the reference RR model (fold band included: the fold-aware step removes the
    /// halving per step there) and on the three six-joint test models; eight plain steps from the
    /// seed, the former default, also reach 100 % but cost twice as much. M7 (dp) cost at N = 256:
    /// about 4.8 evaluations (the start, three evaluations with the exact Jacobian, one
    /// position-only; BENCHMARKS.md "Compensation"). On a trained model whose momenta cancel (the
    /// RR demo's evidence kernels) k1's evaluation is itself noisy at the 1e-9 level and the start
    /// is farther from k1's inverse than the seed: `cbd-trainer commanded` RR gives commanded
    /// error 1.10e-8 (forward 1.02e-8, bound 1.2×) against 1.05e-8 with the former default. Not
    /// guarded (`start_guard` hands the remaining steps to the seed, too few there: 1.1e-6).
    /// Tolerance [`reach_tolerance`]: 1e-9 of the model's task scale (the RMS radius of its training
    /// positions, a length of the arm's size), or the model's own precision when that is coarser; extrapolation below support 0.05 (as `cbd eval`); singular
    /// below conditioning 1e-6.
    pub fn for_model(cal: &Calibrator<'_>) -> CompensateOptions {
        CompensateOptions {
            inverse_flow_start: true,
            iterations: 4,
            start_corrections: 0,
            chord_steps: 0,
            fold_steps: true,
            start_guard: false,
            tolerance: reach_tolerance(cal),
            extrapolation_threshold: 0.05,
            singular_conditioning: 1e-6,
        }
    }
}

/// What `reached` means by default: within 1e-9 of the task scale, or within the model's own
/// precision ([`Calibrator::precision`]) when that is coarser — a target is reached when the
/// residual is as small as the model's own evaluation can resolve (issue 25).
pub fn reach_tolerance(cal: &Calibrator<'_>) -> f64 {
    let fixed = cal.model.normalisation.length_to_user(1e-9);
    if cal.precision > fixed {
        cal.precision
    } else {
        fixed
    }
}

/// The outcome of [`Calibrator::compensate`]: the command is in the caller's `out`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Compensation {
    /// |k1(q) − target| at the command, user units (∞ when it overflows).
    pub residual: f64,
    /// The residual is within the tolerance.
    pub reached: bool,
    /// Dk1 at the command is (nearly) rank-deficient: the target is at the workspace's boundary
    /// or the arm at a singular configuration.
    pub singular: bool,
    /// The command is far from every measured configuration: k1 extrapolates there.
    pub extrapolating: bool,
    /// Kernel support at the command ([`Evaluation::support`]).
    pub support: f64,
    /// [`conditioning`] of Dk1 at the command.
    pub conditioning: f64,
}

impl Compensation {
    /// Reached, regular and inside the calibrated region.
    pub fn is_ok(&self) -> bool {
        self.reached && !self.singular && !self.extrapolating
    }
}

/// One iterate's figures, kept for the best one.
#[derive(Clone, Copy)]
struct Iterate {
    q: SVector<f64, NJ>,
    residual: f64,
    support: f64,
    conditioning: f64,
}

/// [`Calibrator::compensate_with`] with [`CompensateOptions::for_model`].
pub fn compensate(cal: &mut Calibrator<'_>, target: &[f64], seed: &[f64], out: &mut [f64]) -> Result<Compensation, Error> {
    let options = CompensateOptions::for_model(cal);
    compensate_with(cal, target, seed, out, &options)
}

/// Writes to `out` the joint command q with k1(q) = `target`: from the inverse-flow start
/// ([`Calibrator::inverse_flow_start`], `seed` choosing the nominal branch; the seed itself
/// without `options.inverse_flow_start` or when the start fails), `options.iterations` damped
/// minimum-norm Gauss–Newton steps ([`crate::inverse_kinematics::damped_min_norm_step`],
/// fold-aware with `options.fold_steps`) on the exact Jacobian Dk1 and `options.chord_steps`
/// with the last one, q ← q + Dk1ᵀ (Dk1 Dk1ᵀ + λ² I)⁻¹ (target − k1(q)).
/// With more joints than task coordinates (n > m) each step is the minimum-norm one, so the command stays near the seed
/// (its orientation and branch). The iterate with the smallest residual is returned, with
/// flags instead of an error when the target is not reached, Dk1 is singular there or the
/// command lies outside the calibrated region.
///
/// Errors: wrong lengths ([`Error::TargetDimension`], [`Error::QueryDimension`]), a non-finite
/// target or seed ([`Error::NonFiniteTarget`], [`Error::NonFiniteQuery`]), and the
/// evaluation's own errors.
pub fn compensate_with(
    cal: &mut Calibrator<'_>,
    target: &[f64],
    seed: &[f64],
    out: &mut [f64],
    options: &CompensateOptions,
) -> Result<Compensation, Error> {
    let (m, n) = (cal.dims.m, cal.dims.n);
    if target.len() != m {
        return Err(Error::TargetDimension { expected: m, found: target.len() });
    }
    if seed.len() != n {
        return Err(Error::QueryDimension { expected: n, found: seed.len() });
    }
    if out.len() != n {
        return Err(Error::QueryDimension { expected: n, found: out.len() });
    }
    if let Some(index) = target.iter().position(|v| !v.is_finite()) {
        return Err(Error::NonFiniteTarget { index });
    }
    if let Some(index) = seed.iter().position(|v| !v.is_finite()) {
        return Err(Error::NonFiniteQuery { index });
    }
    if n > NJ || m > MT {
        return Err(Error::Internal);
    }
    let target_v = padded_target(target);
    let scale = cal.model.normalisation.task_scale;
    // k1⁻¹ = φ ∘ k0⁻¹ ∘ ψ⁻¹: inverse-flow start (the seed when it fails: a target whose
    // pull-back k0 cannot reach stays with Newton from the seed).
    let mut start = [0.0; NJ];
    let start_slice = start.get_mut(..n).ok_or(Error::Internal)?;
    let from_flows = options.inverse_flow_start && inverse_flow_start(cal, target, seed, start_slice, NOMINAL_ITERATIONS).is_ok();
    let mut q = SVector::<f64, NJ>::zeros();
    for (dst, s) in q.iter_mut().zip(if from_flows { start_slice.iter() } else { seed.iter() }) {
        *dst = *s;
    }
    let mut best = Iterate { q, residual: f64::INFINITY, support: 0.0, conditioning: 0.0 };
    let mut query = [0.0; NJ];
    // The guard: the seed's own residual (position only), which the start must beat.
    let mut seed_q = SVector::<f64, NJ>::zeros();
    for (dst, s) in seed_q.iter_mut().zip(seed.iter()) {
        *dst = *s;
    }
    let mut seed_residual = f64::INFINITY;
    if from_flows && options.start_guard {
        let e = evaluate_transported(cal, seed)?;
        let (position, transported) = evaluation_matrices(&e, m, n);
        seed_residual = (target_v - position).norm();
        if seed_residual < best.residual {
            best = Iterate { q: seed_q, residual: seed_residual, support: e.support(), conditioning: conditioning(&transported, m) };
        }
    }
    // Defect correction of the start: the inverse flows from the target moved by the miss.
    let mut moved_target = target_v;
    for _ in 0..if from_flows { options.start_corrections } else { 0 } {
        for (dst, v) in query.iter_mut().zip(q.iter()) {
            *dst = *v;
        }
        let e = evaluate_transported(cal, query.get(..n).ok_or(Error::Internal)?)?;
        let (position, transported) = evaluation_matrices(&e, m, n);
        let r = target_v - position;
        let residual = r.norm();
        if residual < best.residual {
            best = Iterate { q, residual, support: e.support(), conditioning: conditioning(&transported, m) };
        }
        moved_target += r;
        let moved = moved_target.as_slice().get(..m).ok_or(Error::Internal)?;
        if inverse_flow_start(cal, moved, seed, start_slice, NOMINAL_ITERATIONS).is_ok() {
            for (dst, s) in q.iter_mut().zip(start_slice.iter()) {
                *dst = *s;
            }
        }
    }
    let mut jacobian = SMatrix::<f64, MT, NJ>::zeros();
    let evaluations = options.iterations + options.chord_steps;
    for step in 0..=evaluations {
        let exact = step < options.iterations;
        for (dst, v) in query.iter_mut().zip(q.iter()) {
            *dst = *v;
        }
        let qs = query.get(..n).ok_or(Error::Internal)?;
        // Chord steps and the last iterate need only the position: eq. (19)'s transported
        // J(1) stands in for Dk1 in their conditioning (same position bits, no tangents).
        let e = if exact { evaluate(cal, qs)? } else { evaluate_transported(cal, qs)? };
        let (position, this_jacobian) = evaluation_matrices(&e, m, n);
        if exact {
            jacobian = this_jacobian;
        }
        let r = target_v - position;
        let residual = r.norm();
        if residual < best.residual {
            best = Iterate { q, residual, support: e.support(), conditioning: conditioning(&this_jacobian, m) };
        }
        if step == 0 && seed_residual < residual {
            // The start lost to the seed: the remaining evaluations go to the seed.
            q = seed_q;
            continue;
        }
        if step < evaluations {
            // The fold-aware direction on exact steps (chord steps reuse an old Jacobian, whose
            // singular pair no longer sits at q), bounded like every Gauss–Newton step.
            let direction = if exact && options.fold_steps {
                fold_step(cal, &q, &jacobian, &r, m, n, scale)
            } else {
                damped_min_norm_direction(&jacobian, &r, m, scale)
            };
            if let Some(dq) = direction.and_then(|d| bounded_step(d, |j| cal.model.nominal.is_revolute(j))) {
                q += dq;
            }
        }
    }
    // A residual that overflows (a target near f64::MAX) is never below another: `best` is
    // then the start with residual ∞, support and conditioning 0, flagged on every count.
    for (dst, v) in out.iter_mut().zip(best.q.iter()) {
        *dst = *v;
    }
    Ok(Compensation {
        residual: best.residual,
        // A residual that overflowed is never reached, whatever the tolerance (a model whose
        // precision bound is infinite resolves nothing).
        reached: best.residual.is_finite() && best.residual <= options.tolerance,
        singular: !(best.conditioning >= options.singular_conditioning),
        extrapolating: !(best.support >= options.extrapolation_threshold),
        support: best.support,
        conditioning: best.conditioning,
    })
}

/// The damped minimum-norm step with its component along Dk1's smallest right singular
/// vector v replaced by the nearer root of the quadratic model along it
/// ([`crate::inverse_kinematics::fold`]), before the revolute bound.
fn fold_step(
    cal: &Calibrator<'_>,
    q: &SVector<f64, NJ>,
    jacobian: &SMatrix<f64, MT, NJ>,
    r: &SVector<f64, MT>,
    m: usize,
    n: usize,
    scale: f64,
) -> Option<SVector<f64, NJ>> {
    let mut dq = damped_min_norm_direction(jacobian, r, m, scale)?;
    if let Some((sigma, u, v)) = smallest_singular_pair(jacobian, m) {
        // Of tool point 0, the point `evaluate` compensates (the model itself without tool points).
        let curvature = crate::kinematics::with_tool_point(&cal.model.nominal, 0, |nominal| nominal_curvature(nominal, q, &u, &v, m, n))
            .unwrap_or(f64::NAN);
        let rho = u.dot(r);
        if let (true, Some(t)) = (curvature.is_finite(), fold_root(sigma, curvature, rho)) {
            dq += v * (t - v.dot(&dq));
        }
    }
    Some(dq)
}

fn evaluation_matrices(e: &Evaluation, m: usize, n: usize) -> (SVector<f64, MT>, SMatrix<f64, MT, NJ>) {
    let mut position = [0.0; MT];
    let mut jacobian = [[0.0; NJ]; MT];
    for (a, (p, row)) in position.iter_mut().zip(jacobian.iter_mut()).enumerate().take(m) {
        *p = e.position.get(a).copied().unwrap_or(f64::NAN);
        for (d, v) in row.iter_mut().enumerate().take(n) {
            *v = e.jacobian.get((a, d)).copied().unwrap_or(f64::NAN);
        }
    }
    matrices_of(&position, &jacobian, m, n)
}

//! The iterations: the linearised model's closed-form start, then (damped) Gauss–Newton steps with
//! chord steps while they pay, until the energy or the predictions stop moving.

use super::problem::{model_energy, Evaluated, Problem, Timers};
use super::{CbdOptions, FitError, IterationLog, FIXED_SPLIT};
use crate::report::progress::FitProgress;
use crate::solver::step::StepFactor;
use faer::Mat;
use std::time::Instant;

/// Marquardt damping λ after the first failed Gauss–Newton step, then ×DAMPING_GROWTH per failure
/// (λ D² is relative to JᵀJ/σ², so tiny values already matter).
const FIRST_DAMPING: f64 = 1e-18;
const DAMPING_GROWTH: f64 = 100.0;
/// Proximal term μ·mean(diag K)·|δ|² of every step (grown if K + μ I does not factor): keeps steps out
/// of directions that neither data nor regulariser determine to working precision.
const PROXIMAL: f64 = 1e-11;
/// A chord step (reusing an older Jacobian's factorisation) follows a step whose energy decrement
/// is at most this fraction of the previous one; slower progress asks for the exact Jacobian.
const CHORD_CONTRACTION: f64 = 0.5;

/// The per-iteration log, the progress bar and (verbose, no bar) one printed line per iteration.
pub(super) struct Recorder {
    pub log: Vec<IterationLog>,
    progress: FitProgress,
    print_lines: bool,
    start: Instant,
    task_scale: f64,
}

impl Recorder {
    pub fn new(opts: &CbdOptions, start: Instant) -> Self {
        // A bar on a terminal; plain lines when verbose output goes to a pipe or file.
        let progress = FitProgress::new(opts.max_iterations, !opts.verbose, "");
        let print_lines = opts.verbose && !progress.is_visible();
        Recorder { log: Vec::new(), progress, print_lines, start, task_scale: opts.normalisation.task_scale }
    }

    /// Logs iteration `iteration` at `e`; `detail` ends the printed line.
    fn record(&mut self, problem: &Problem, iteration: usize, e: &Evaluated, damping: f64, detail: &str) {
        let train_rms = problem.rms(&e.residual, self.task_scale);
        let seconds = self.start.elapsed().as_secs_f64();
        self.log.push(IterationLog { iteration, energy: e.energy, regulariser: e.regulariser, train_rms, damping, seconds });
        self.progress.update(iteration, e.energy, train_rms);
        if self.print_lines {
            errln!("iter {iteration:2}  energy {:.6e}  train rms {train_rms:.3e}{detail}", e.energy);
        }
    }

    pub fn finish(&self, stop_reason: &str) {
        self.progress.finish(stop_reason);
    }
}

/// Where the iterations stopped.
pub(super) struct Outcome {
    /// Search coordinates.
    pub p: Vec<f64>,
    pub current: Evaluated,
    pub iterations: usize,
    pub converged: bool,
    pub stop_reason: String,
}

/// Minimises energy (16) from P0 = 0.
pub(super) fn minimise(problem: &Problem, opts: &CbdOptions, linear_scheme: bool, recorder: &mut Recorder) -> Result<Outcome, FitError> {
    let mut p = vec![0.0; problem.space.dim()];
    let current = problem.evaluate(&p).ok_or(FitError::Diverged { iteration: 0, damping: 0.0 })?;
    recorder.record(problem, 0, &current, 0.0, "");
    // Warm start: at P0 = 0 the model is linear, so the first Gauss–Newton step is the
    // linearised (kernel) model's solution; its Jacobian is known in closed form.
    let jac = problem.space.start_jacobian(crate::solver::regulariser::linear_response(problem.cp));
    let mut descent = Descent::new(current, jac);
    let (mut iterations, mut converged, mut stop_reason) = (0, false, String::from("iteration limit"));
    let mut first_iteration = 1;
    // Hamiltonian laws: the response at P0 = 0 is K_lin itself, so the linearised model's optimum
    // (the GP posterior mean) is P0 = (K_lin + σ² I)⁻¹ (y − k0) in closed form. Exact for Euler × 1;
    // the start of every other scheme. Steps on the stacked least squares reach it only slowly when
    // the evidence picks nearly singular kernels (σ² far below the proximal term's scale).
    if opts.law.joint_field_sign() < 0.0 {
        let r: Vec<f64> = descent.current.residual.iter().map(|v| -v * problem.sigma).collect();
        let p_lin = Timers::time(&problem.timers.solve, || problem.space.linearised_solution(problem.sigma, &r));
        let better = p_lin.and_then(|p_lin| problem.evaluate(&p_lin).map(|e| (p_lin, e)));
        if let Some((p_lin, e)) = better.filter(|(_, e)| e.energy < descent.current.energy) {
            p = p_lin;
            descent.current = e;
            iterations = 1;
            first_iteration = 2;
            recorder.record(problem, 1, &descent.current, 0.0, "  linearised model, closed form");
            if linear_scheme {
                converged = true;
                stop_reason = "closed form (the linearised model: Euler × 1)".into();
                first_iteration = usize::MAX;
            } else {
                descent.jac = problem.exact_jacobian(&descent.current.flow);
            }
        }
    }
    for iteration in first_iteration..=opts.max_iterations {
        iterations = iteration;
        let Some(step) = descent.step(problem, &mut p, iteration, linear_scheme)? else {
            converged = true;
            stop_reason = "no further decrease at any damping (converged to rounding)".into();
            break;
        };
        let kind = if step.exact { "exact J" } else { "chord" };
        let detail = format!("  damping {:.1e}  {kind}  {:.1} s", step.damping, recorder.start.elapsed().as_secs_f64());
        recorder.record(problem, iteration, &descent.current, step.damping, &detail);
        let small = step.relative < opts.relative_tolerance;
        if small && step.exact {
            // Converged: a step with the exact Jacobian gains (almost) nothing.
            converged = true;
            stop_reason = format!("relative energy decrease below {:.0e}", opts.relative_tolerance);
            break;
        }
        if step.exact && step.moved < opts.prediction_tolerance {
            // Settled: what is left of the energy's decrease is the regulariser in directions the
            // data do not resolve to working precision, which the (necessary) damping lets converge
            // only linearly. (An absolute length, not a multiple of σ: σ and the kernel amplitudes
            // can be rescaled together without changing the model.)
            converged = true;
            stop_reason = format!("no training prediction moved by {:.0e} (normalised units)", opts.prediction_tolerance);
            break;
        }
        descent.prepare_next(problem, step.decrease, small, linear_scheme, iteration < opts.max_iterations);
    }
    Ok(Outcome { p, current: descent.current, iterations, converged, stop_reason })
}

/// An accepted step.
struct Step {
    decrease: f64,
    relative: f64,
    /// Largest change of a training prediction, internal (normalised) length units.
    moved: f64,
    /// Taken with the Jacobian at the point it started from (else a chord step).
    exact: bool,
    /// The damping the step was taken with.
    damping: f64,
}

/// The Levenberg–Marquardt state between iterations.
struct Descent {
    current: Evaluated,
    jac: Mat<f64>,
    /// Whether `jac` is the derivative at the current P0 (else it is an older one: a chord step).
    jacobian_is_current: bool,
    /// The step's factorisation for the Jacobian in `jac` and damping λ, reused by chord steps.
    factor: Option<StepFactor>,
    /// The largest damping whose step failed with an exact Jacobian: relaxing stops above it.
    failed_damping: Option<f64>,
    /// Pure Gauss–Newton (the regulariser keeps it well posed); Marquardt damping only after a failed step.
    damping: f64,
    previous_decrease: f64,
    chords_pay: bool,
}

impl Descent {
    fn new(current: Evaluated, jac: Mat<f64>) -> Self {
        Descent {
            current,
            jac,
            jacobian_is_current: true,
            factor: None,
            failed_damping: None,
            damping: 0.0,
            previous_decrease: f64::INFINITY,
            chords_pay: true,
        }
    }

    /// One iteration from `p` (updated in place): a Gauss–Newton step as a least-squares problem,
    /// never forming JᵀJ (which would square the condition number): minimise
    /// |J δ/σ + r|² + (P + δ)ᵀ K (P + δ) + λ |D δ|², D² = diag(JᵀJ/σ² + K) (Marquardt scaling; see
    /// `step`), damping raised until the energy falls. None when it falls at no damping.
    fn step(&mut self, problem: &Problem, p: &mut Vec<f64>, iteration: usize, linear_scheme: bool) -> Result<Option<Step>, FitError> {
        let (k_reg, sigma) = (&problem.space.k_reg, problem.sigma);
        let mut accepted = None;
        let mut exact = self.jacobian_is_current;
        loop {
            let step = Timers::time(&problem.timers.solve, || -> Result<Vec<f64>, FitError> {
                if self.factor.as_ref().is_none_or(|f| f.damping != self.damping) {
                    let factor =
                        StepFactor::new(&self.jac, k_reg, sigma, self.damping, problem.space.damping_scale(), PROXIMAL, FIXED_SPLIT);
                    self.factor = Some(factor.ok_or(FitError::Singular { iteration, damping: self.damping })?);
                }
                Ok(self.factor.as_ref().map(|f| f.step(k_reg, &self.current.residual, p)).unwrap_or_default())
            })?;
            if step.iter().all(|v| v.is_finite()) {
                let trial: Vec<f64> = p.iter().zip(&step).map(|(v, d)| v + d).collect();
                if let Some(e) = problem.evaluate(&trial).filter(|e| e.energy < self.current.energy) {
                    // The decrease the Gauss–Newton model promised, for the gain ratio below.
                    let predicted = self.current.energy - model_energy(&self.jac, k_reg, sigma, &self.current.residual, &step, &trial);
                    accepted = Some((trial, e, predicted));
                    break;
                }
            }
            if !self.jacobian_is_current {
                // A chord step (older Jacobian) failed: take the exact Jacobian here instead of
                // damping, and no more chord steps (each failure costs a flow).
                self.chords_pay = false;
                self.jac = problem.exact_jacobian(&self.current.flow);
                self.factor = None;
                self.jacobian_is_current = true;
                exact = true;
                continue;
            }
            self.failed_damping = Some(self.failed_damping.map_or(self.damping, |f| f.max(self.damping)));
            self.damping = if self.damping == 0.0 { FIRST_DAMPING } else { self.damping * DAMPING_GROWTH };
            if self.damping > 1e12 {
                break;
            }
        }
        let Some((trial, e, predicted)) = accepted else {
            if iteration == 1 {
                return Err(FitError::Diverged { iteration, damping: self.damping });
            }
            return Ok(None);
        };
        let decrease = self.current.energy - e.energy;
        let relative = decrease / self.current.energy;
        if decrease > 0.5 * predicted {
            // The model was good at this damping: lower levels that failed earlier, elsewhere in
            // the landscape, may be tried again (otherwise one early failure at a high level pins
            // the damping there for the rest of the fit).
            self.failed_damping = None;
        }
        let moved = sigma * self.current.residual.iter().zip(&e.residual).fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
        *p = trial;
        self.current = e;
        self.jacobian_is_current = linear_scheme;
        let damping = self.damping;
        // Damping relaxes tenfold per success, back to pure Gauss–Newton, but not down to a level
        // that already failed (each new level costs a factorisation).
        self.damping = match damping / 10.0 {
            _ if damping == 0.0 => 0.0,
            relaxed if self.failed_damping.is_some_and(|f| relaxed <= f) => damping,
            relaxed if relaxed < FIRST_DAMPING => 0.0,
            relaxed => relaxed,
        };
        Ok(Some(Step { decrease, relative, moved, exact, damping }))
    }

    /// After an accepted step that `decrease`d the energy: keep the factorisation for a chord step
    /// while the decrements shrink fast (at least CHORD_CONTRACTION per step); otherwise form the
    /// exact Jacobian here (unless no iteration follows).
    fn prepare_next(&mut self, problem: &Problem, decrease: f64, small: bool, linear_scheme: bool, more: bool) {
        let chord = self.chords_pay && !small && decrease <= CHORD_CONTRACTION * self.previous_decrease;
        self.previous_decrease = decrease;
        if !linear_scheme && !chord {
            self.factor = None;
            if more {
                self.jac = problem.exact_jacobian(&self.current.flow);
                self.jacobian_is_current = true;
            }
        }
    }
}

//! The iterations: the linearised model's closed-form start, then (damped) Gauss–Newton steps with
//! chord steps while they pay, until the energy or the predictions stop moving.

use super::problem::{model_energy, Evaluated, Problem, Timers};
use super::{CbdOptions, FitError, IterationLog};
use crate::numeric::levenberg_marquardt as lm;
use crate::numeric::FIXED_SPLIT;
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
    normalisation: cbd_protocol::Normalisation,
}

impl Recorder {
    pub fn new(opts: &CbdOptions, start: Instant) -> Self {
        // A bar on a terminal; plain lines when verbose output goes to a pipe or file.
        let progress = FitProgress::new(opts.solver.max_iterations, !opts.solver.verbose, "");
        let print_lines = opts.solver.verbose && !progress.is_visible();
        Recorder { log: Vec::new(), progress, print_lines, start, normalisation: opts.normalisation.clone() }
    }

    /// Logs iteration `iteration` at `e`; `detail` ends the printed line.
    fn record(&mut self, problem: &Problem, iteration: usize, e: &Evaluated, damping: f64, detail: &str) {
        let train_rms = problem.rms(&e.residual, &self.normalisation);
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
    let mut current = problem.evaluate(&p).ok_or(FitError::Diverged { iteration: 0, damping: 0.0 })?;
    recorder.record(problem, 0, &current, 0.0, "");
    // Warm start: at P0 = 0 the model is linear, so the first Gauss–Newton step is the
    // linearised (kernel) model's solution; its Jacobian is known in closed form.
    let mut jac = problem.space.start_jacobian(crate::solver::regulariser::linear_response(problem.cp));
    let mut first_iteration = 1;
    // Hamiltonian laws: the response at P0 = 0 is K_lin itself, so the linearised model's optimum
    // (the GP posterior mean) is P0 = (K_lin + σ² I)⁻¹ (y − k0) in closed form. Exact for Euler × 1;
    // the start of every other scheme. Steps on the stacked least squares reach it only slowly when
    // the evidence picks nearly singular kernels (σ² far below the proximal term's scale).
    if opts.solver.law.joint_field_sign() < 0.0 {
        let r: Vec<f64> = current.residual.iter().map(|v| -v * problem.sigma).collect();
        let p_lin = Timers::time(&problem.timers.solve, || problem.space.linearised_solution(problem.sigma, &r));
        let better = p_lin.and_then(|p_lin| problem.evaluate(&p_lin).map(|e| (p_lin, e)));
        if let Some((p_lin, e)) = better.filter(|(_, e)| e.energy < current.energy) {
            p = p_lin;
            current = e;
            first_iteration = 2;
            recorder.record(problem, 1, &current, 0.0, "  linearised model, closed form");
            if linear_scheme {
                let stop_reason = "closed form (the linearised model: Euler × 1)".into();
                return Ok(Outcome { p, current, iterations: 1, converged: true, stop_reason });
            }
            jac = problem.exact_jacobian(&current.flow);
        }
    }
    let options = lm::Options {
        damping: lm::Damping::Marquardt {
            first: FIRST_DAMPING,
            growth: DAMPING_GROWTH,
            limit: 1e12,
            relax: lm::Relax::Remembering { divisor: 10.0 },
        },
        acceptance: lm::Acceptance::Decrease,
        counting: lm::Counting::Steps,
        first_iteration,
        max_iterations: opts.solver.max_iterations,
    };
    let mut steps = FlowSteps {
        problem,
        opts,
        linear_scheme,
        recorder,
        jac,
        jacobian_is_current: true,
        exact: true,
        factor: None,
        previous_decrease: f64::INFINITY,
        chords_pay: true,
    };
    let found = lm::minimise(&mut steps, p, current, &options)?;
    let (iterations, converged, stop_reason) = match found.stop {
        lm::Stop::Converged(words) => (found.iterations, true, words),
        lm::Stop::NoProgress if found.iterations == 1 => {
            return Err(FitError::Diverged { iteration: 1, damping: found.damping });
        }
        lm::Stop::NoProgress | lm::Stop::NoStep => {
            (found.iterations, true, "no further decrease at any damping (converged to rounding)".into())
        }
        lm::Stop::IterationLimit => (found.iterations, false, "iteration limit".into()),
    };
    Ok(Outcome { p: found.x, current: found.at, iterations, converged, stop_reason })
}

/// The fit as the least-squares driver sees it: each iteration a Gauss–Newton step as a least-squares
/// problem, never forming JᵀJ (which would square the condition number): minimise
/// |J δ/σ + r|² + (P + δ)ᵀ K (P + δ) + λ |D δ|², D² = diag(JᵀJ/σ² + K) (Marquardt scaling; see
/// `step`), with chord steps (an older Jacobian's factorisation) while they pay.
struct FlowSteps<'p, 'a, 'r> {
    problem: &'p Problem<'a>,
    opts: &'p CbdOptions,
    linear_scheme: bool,
    recorder: &'r mut Recorder,
    jac: Mat<f64>,
    /// Whether `jac` is the derivative at the current P0 (else it is an older one: a chord step).
    jacobian_is_current: bool,
    /// Whether this iteration's step is taken with the Jacobian at the point it started from.
    exact: bool,
    /// The step's factorisation for the Jacobian in `jac` and damping λ, reused by chord steps.
    factor: Option<StepFactor>,
    previous_decrease: f64,
    chords_pay: bool,
}

impl lm::Problem for FlowSteps<'_, '_, '_> {
    type Eval = Evaluated;
    type Error = FitError;

    fn cost(&self, at: &Evaluated) -> f64 {
        at.energy
    }

    fn prepare(&mut self, _p: &[f64], _at: &Evaluated) -> Result<(), FitError> {
        self.exact = self.jacobian_is_current;
        Ok(())
    }

    fn propose(&mut self, p: &[f64], at: &Evaluated, damping: f64, iteration: usize) -> Result<Option<lm::Step>, FitError> {
        let problem = self.problem;
        let (k_reg, sigma) = (&problem.space.k_reg, problem.sigma);
        let delta = Timers::time(&problem.timers.solve, || -> Result<Vec<f64>, FitError> {
            if self.factor.as_ref().is_none_or(|f| f.damping != damping) {
                let factor = StepFactor::new(&self.jac, k_reg, sigma, damping, problem.space.damping_scale(), PROXIMAL, FIXED_SPLIT);
                self.factor = Some(factor.ok_or(FitError::Singular { iteration, damping })?);
            }
            Ok(self.factor.as_ref().map(|f| f.step(k_reg, &at.residual, p)).unwrap_or_default())
        })?;
        Ok(Some(lm::Step { delta, predicted: None }))
    }

    fn evaluate(&mut self, trial: &[f64], delta: &[f64]) -> Result<Option<Evaluated>, FitError> {
        Ok(if delta.iter().all(|v| v.is_finite()) { self.problem.evaluate(trial) } else { None })
    }

    /// The decrease the Gauss–Newton model promised, for the gain ratio.
    fn predicted_decrease(&mut self, _p: &[f64], at: &Evaluated, delta: &[f64], trial: &[f64]) -> f64 {
        let (k_reg, sigma) = (&self.problem.space.k_reg, self.problem.sigma);
        at.energy - model_energy(&self.jac, k_reg, sigma, &at.residual, delta, trial)
    }

    /// A chord step (older Jacobian) failed: take the exact Jacobian here instead of damping, and no
    /// more chord steps (each failure costs a flow).
    fn rejected(&mut self, at: &Evaluated) -> bool {
        if self.jacobian_is_current {
            return false;
        }
        self.chords_pay = false;
        self.jac = self.problem.exact_jacobian(&at.flow);
        self.factor = None;
        self.jacobian_is_current = true;
        self.exact = true;
        true
    }

    fn accepted(&mut self, step: lm::Accepted<'_, Evaluated>) -> Option<String> {
        let (problem, opts, iteration) = (self.problem, self.opts, step.iteration);
        let (from, e) = (step.from, step.to);
        let decrease = step.decrease;
        let relative = decrease / from.energy;
        // The largest change of a training prediction, internal (normalised) length units.
        let moved = problem.sigma * from.residual.iter().zip(&e.residual).fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
        self.jacobian_is_current = self.linear_scheme;
        let kind = if self.exact { "exact J" } else { "chord" };
        let detail = format!("  damping {:.1e}  {kind}  {:.1} s", step.damping, self.recorder.start.elapsed().as_secs_f64());
        self.recorder.record(problem, iteration, e, step.damping, &detail);
        let small = relative < opts.solver.relative_tolerance;
        if small && self.exact {
            // Converged: a step with the exact Jacobian gains (almost) nothing.
            return Some(format!("relative energy decrease below {:.0e}", opts.solver.relative_tolerance));
        }
        if self.exact && moved < opts.solver.prediction_tolerance {
            // Settled: what is left of the energy's decrease is the regulariser in directions the
            // data do not resolve to working precision, which the (necessary) damping lets converge
            // only linearly. (An absolute length, not a multiple of σ: σ and the kernel amplitudes
            // can be rescaled together without changing the model.)
            return Some(format!("no training prediction moved by {:.0e} (normalised units)", opts.solver.prediction_tolerance));
        }
        // Keep the factorisation for a chord step while the decrements shrink fast (at least
        // CHORD_CONTRACTION per step); otherwise form the exact Jacobian here (unless no iteration
        // follows).
        let chord = self.chords_pay && !small && decrease <= CHORD_CONTRACTION * self.previous_decrease;
        self.previous_decrease = decrease;
        if !self.linear_scheme && !chord {
            self.factor = None;
            if iteration < opts.solver.max_iterations {
                self.jac = problem.exact_jacobian(&e.flow);
                self.jacobian_is_current = true;
            }
        }
        None
    }
}

//! The trainer's one nonlinear least-squares driver (issue 41; docs/DESIGN.md §3, "One least-squares
//! driver"): Levenberg–Marquardt on a [`Problem`] — the problem says how to evaluate a point and how
//! to step from it at a damping; the driver owns the loop, the acceptance test, the damping and the
//! reason it stopped. It serves the flow fit (`solver/fit/iterate.rs`), the expansion's multi-step fit
//! (`expansion/flow_fit.rs`), DH calibration (`parametric/least_squares.rs`) and diagnose's refinement
//! (`diagnose/refine.rs`).
//!
//! One damping policy, [`Damping`], whose parameters each caller passes: the rules the four loops used
//! before they shared this one are kept as its variants and parameters, so every caller's figures stay
//! the same to the last bit (the blob hashes are pinned).

/// How the damping λ moves between trials: raised after a rejected trial until one is accepted or
/// the limit is passed, relaxed after an accepted one.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Damping {
    /// Marquardt's rule from pure Gauss–Newton: λ = 0 until a trial is rejected, then `first`,
    /// × `growth` per further rejection; no progress once λ > `limit`. Relaxed by `relax`.
    Marquardt { first: f64, growth: f64, limit: f64, relax: Relax },
    /// Nielsen's rule: λ = `initial` × the problem's [`Problem::damping_scale`] (the largest
    /// eigenvalue of the scaled JᵀJ) at the first linearisation and after a restart; × ν on a
    /// rejection, ν doubling (ν = 2 after every acceptance, not reset by a restart); × max(⅓, 1 − (2ρ − 1)³)
    /// on an acceptance with gain ratio ρ; no progress once λ > `limit` × that scale (at least 1e-300).
    Nielsen { initial: f64, limit: f64 },
    /// Undamped Gauss–Newton with backtracking: the step proposed once per iteration, its length
    /// t = 1 × `shrink` per rejection; no progress once t is no longer above `shortest`. The iteration
    /// counts as one whatever its trials ([`Counting::Steps`] is implied).
    Backtracking { shrink: f64, shortest: f64 },
}

/// How Marquardt's λ relaxes after an accepted step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Relax {
    /// λ × factor (never back to exactly zero once raised).
    Scale(f64),
    /// λ / divisor, back to pure Gauss–Newton below `first`, but not down to a level rejected since
    /// the last step that gained more than half what its linear model predicted (each new level
    /// costs the caller a factorisation).
    Remembering { divisor: f64 },
}

/// When a trial point is accepted.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Acceptance {
    /// Its cost is finite and below the current one.
    Decrease,
    /// Its cost is finite and not above the current one.
    NoIncrease,
}

/// What one iteration is.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Counting {
    /// Every trial, accepted or rejected.
    Trials,
    /// An accepted step with the rejected trials before it (raising the damping within the iteration).
    Steps,
}

/// The driver's parameters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Options {
    pub damping: Damping,
    pub acceptance: Acceptance,
    pub counting: Counting,
    /// The first iteration's number (2 when the caller took iteration 1 itself).
    pub first_iteration: usize,
    pub max_iterations: usize,
}

/// A proposed step from the current point.
pub struct Step {
    /// Added to the parameters (× t under [`Damping::Backtracking`]).
    pub delta: Vec<f64>,
    /// The cost decrease the linear model predicts, when the proposal knows it; else, when the
    /// damping needs it, [`Problem::predicted_decrease`] is asked after an acceptance.
    pub predicted: Option<f64>,
}

/// An accepted step, as the problem's convergence test sees it.
pub struct Accepted<'a, E> {
    pub iteration: usize,
    pub from: &'a E,
    pub to: &'a E,
    /// cost(from) − cost(to).
    pub decrease: f64,
    /// The damping (the step length under backtracking) the step was taken with.
    pub damping: f64,
}

/// Why the iterations stopped.
#[derive(Debug, Clone, PartialEq)]
pub enum Stop {
    /// An accepted step passed the problem's convergence test (its words).
    Converged(String),
    /// The problem had no step left to propose (negligible, or predicting no decrease).
    NoStep,
    /// No trial was accepted at any damping up to the policy's limit.
    NoProgress,
    /// The iteration limit.
    IterationLimit,
}

/// Where the iterations stopped.
pub struct Outcome<E> {
    pub x: Vec<f64>,
    pub at: E,
    /// The number of the last iteration run (first_iteration − 1 when none ran).
    pub iterations: usize,
    pub stop: Stop,
    /// The damping at the stop (after the last raise when no progress was made).
    pub damping: f64,
}

/// A nonlinear least-squares problem over parameters x, as the driver needs it.
pub trait Problem {
    /// A point's evaluation: residual, cost and whatever the problem keeps with them.
    type Eval;
    type Error;

    /// The cost minimised (½|r|², or |r|², plus any regulariser).
    fn cost(&self, at: &Self::Eval) -> f64;

    /// Called at the start of every iteration (form the Jacobian here if it is formed per iteration).
    fn prepare(&mut self, _x: &[f64], _at: &Self::Eval) -> Result<(), Self::Error> {
        Ok(())
    }

    /// The scale of [`Damping::Nielsen`]'s λ, read after `prepare`.
    fn damping_scale(&self) -> f64 {
        1.0
    }

    /// The step from `x` at damping λ (ignored under backtracking); None when no step is left.
    fn propose(&mut self, x: &[f64], at: &Self::Eval, damping: f64, iteration: usize) -> Result<Option<Step>, Self::Error>;

    /// The trial point `trial` (reached by `delta`); None when it cannot be evaluated.
    fn evaluate(&mut self, trial: &[f64], delta: &[f64]) -> Result<Option<Self::Eval>, Self::Error>;

    /// The decrease the linear model predicted for an accepted `delta` from `x` to `trial`, when
    /// the proposal did not say.
    fn predicted_decrease(&mut self, _x: &[f64], _at: &Self::Eval, _delta: &[f64], _trial: &[f64]) -> f64 {
        f64::NAN
    }

    /// A trial was rejected: true to retry at the same damping (the problem changed its linearisation).
    fn rejected(&mut self, _at: &Self::Eval) -> bool {
        false
    }

    /// A step was accepted: Some(words) when the iterations have converged.
    fn accepted(&mut self, step: Accepted<'_, Self::Eval>) -> Option<String>;

    /// The driver would stop for `stop` at `at`: true to go on (the problem changed; the damping
    /// starts again).
    fn restart(&mut self, _stop: &Stop, _at: &Self::Eval) -> bool {
        false
    }
}

/// The damping between trials.
struct State {
    /// None until Nielsen's λ is initialised from the scale.
    lambda: Option<f64>,
    nu: f64,
    /// The largest λ rejected (Marquardt, remembering).
    failed: Option<f64>,
}

impl State {
    fn new(rule: Damping) -> Self {
        let lambda = match rule {
            Damping::Nielsen { .. } => None,
            Damping::Marquardt { .. } | Damping::Backtracking { .. } => Some(0.0),
        };
        State { lambda, nu: 2.0, failed: None }
    }

    fn restart(&mut self, rule: Damping) {
        self.lambda = State::new(rule).lambda;
        self.failed = None;
    }

    /// After a rejection: whether the policy's limit is passed.
    fn reject(&mut self, rule: Damping, t: &mut f64, scale: f64) -> bool {
        let lambda = self.lambda.unwrap_or(0.0);
        match rule {
            Damping::Marquardt { first, growth, limit, .. } => {
                self.failed = Some(self.failed.map_or(lambda, |f| f.max(lambda)));
                let raised = if lambda == 0.0 { first } else { lambda * growth };
                self.lambda = Some(raised);
                raised > limit
            }
            Damping::Nielsen { limit, .. } => {
                let raised = lambda * self.nu;
                self.lambda = Some(raised);
                self.nu *= 2.0;
                raised > limit * scale.max(1e-300)
            }
            Damping::Backtracking { shrink, shortest } => {
                *t *= shrink;
                *t <= shortest || t.is_nan()
            }
        }
    }

    /// After an acceptance that decreased the cost by `decrease` of the `predicted`.
    fn accept(&mut self, rule: Damping, decrease: f64, predicted: impl FnOnce() -> f64) {
        let lambda = self.lambda.unwrap_or(0.0);
        match rule {
            Damping::Marquardt { relax: Relax::Scale(factor), .. } => self.lambda = Some(lambda * factor),
            Damping::Marquardt { first, relax: Relax::Remembering { divisor }, .. } => {
                if decrease > 0.5 * predicted() {
                    self.failed = None;
                }
                self.lambda = Some(match lambda / divisor {
                    _ if lambda == 0.0 => 0.0,
                    relaxed if self.failed.is_some_and(|f| relaxed <= f) => lambda,
                    relaxed if relaxed < first => 0.0,
                    relaxed => relaxed,
                });
            }
            Damping::Nielsen { .. } => {
                let rho = decrease / predicted();
                self.lambda = Some(lambda * (1.0f64 / 3.0).max(1.0 - (2.0 * rho - 1.0).powi(3)));
                self.nu = 2.0;
            }
            Damping::Backtracking { .. } => {}
        }
    }
}

fn accepts(rule: Acceptance, trial: f64, current: f64) -> bool {
    trial.is_finite()
        && match rule {
            Acceptance::Decrease => trial < current,
            Acceptance::NoIncrease => trial <= current,
        }
}

/// Minimises `problem` from `x` (evaluated: `at`).
pub fn minimise<P: Problem>(problem: &mut P, mut x: Vec<f64>, mut at: P::Eval, options: &Options) -> Result<Outcome<P::Eval>, P::Error> {
    let rule = options.damping;
    let backtracking = matches!(rule, Damping::Backtracking { .. });
    let counting = if backtracking { Counting::Steps } else { options.counting };
    let mut state = State::new(rule);
    let mut iterations = options.first_iteration.saturating_sub(1);
    let mut stop = Stop::IterationLimit;
    'iterations: for iteration in options.first_iteration..=options.max_iterations {
        iterations = iteration;
        problem.prepare(&x, &at)?;
        if state.lambda.is_none() {
            if let Damping::Nielsen { initial, .. } = rule {
                state.lambda = Some(initial * problem.damping_scale());
            }
        }
        let mut t = 1.0;
        let mut once: Option<Step> = None;
        loop {
            let lambda = state.lambda.unwrap_or(0.0);
            let step = match once.take() {
                Some(step) => step,
                None => match problem.propose(&x, &at, lambda, iteration)? {
                    Some(step) => step,
                    None => {
                        let why = Stop::NoStep;
                        if problem.restart(&why, &at) {
                            state.restart(rule);
                            continue 'iterations;
                        }
                        stop = why;
                        break 'iterations;
                    }
                },
            };
            let trial: Vec<f64> = if backtracking {
                x.iter().zip(&step.delta).map(|(v, s)| v + t * s).collect()
            } else {
                x.iter().zip(&step.delta).map(|(v, d)| v + d).collect()
            };
            let current = problem.cost(&at);
            let evaluated = problem.evaluate(&trial, &step.delta)?;
            if let Some(e) = evaluated.filter(|e| accepts(options.acceptance, problem.cost(e), current)) {
                let decrease = current - problem.cost(&e);
                let used = if backtracking { t } else { lambda };
                let predicted = step.predicted;
                state.accept(rule, decrease, || predicted.unwrap_or_else(|| problem.predicted_decrease(&x, &at, &step.delta, &trial)));
                let converged = problem.accepted(Accepted { iteration, from: &at, to: &e, decrease, damping: used });
                (x, at) = (trial, e);
                let Some(words) = converged else { continue 'iterations };
                let why = Stop::Converged(words);
                if problem.restart(&why, &at) {
                    state.restart(rule);
                    continue 'iterations;
                }
                stop = why;
                break 'iterations;
            }
            if problem.rejected(&at) {
                continue;
            }
            if state.reject(rule, &mut t, problem.damping_scale()) {
                let why = Stop::NoProgress;
                if problem.restart(&why, &at) {
                    state.restart(rule);
                    continue 'iterations;
                }
                stop = why;
                break 'iterations;
            }
            if counting == Counting::Trials {
                continue 'iterations;
            }
            if backtracking {
                once = Some(step);
            }
        }
    }
    Ok(Outcome { x, at, iterations, stop, damping: state.lambda.unwrap_or(0.0) })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Rosenbrock's valley as least squares: r = (10 (x₂ − x₁²), 1 − x₁), minimum 0 at (1, 1);
    /// `broken` makes every trial fail to evaluate.
    struct Rosenbrock {
        broken: bool,
        restarts: usize,
    }

    fn residual(x: &[f64]) -> Vec<f64> {
        vec![10.0 * (x[1] - x[0] * x[0]), 1.0 - x[0]]
    }

    impl Problem for Rosenbrock {
        /// The residual and ½|r|².
        type Eval = (Vec<f64>, f64);
        type Error = ();

        fn cost(&self, at: &Self::Eval) -> f64 {
            at.1
        }

        /// (JᵀJ + λ I) δ = −Jᵀ r, by Cramer's rule.
        fn propose(&mut self, x: &[f64], at: &Self::Eval, damping: f64, _iteration: usize) -> Result<Option<Step>, ()> {
            let (j, r) = ([[-20.0 * x[0], 10.0], [-1.0, 0.0]], &at.0);
            let a = |p: usize, q: usize| j[0][p] * j[0][q] + j[1][p] * j[1][q] + if p == q { damping } else { 0.0 };
            let g = |p: usize| j[0][p] * r[0] + j[1][p] * r[1];
            let det = a(0, 0) * a(1, 1) - a(0, 1) * a(1, 0);
            let delta = vec![-(a(1, 1) * g(0) - a(0, 1) * g(1)) / det, -(a(0, 0) * g(1) - a(1, 0) * g(0)) / det];
            // The linear model's decrease: −gᵀδ − ½ δᵀ JᵀJ δ.
            let jd = [j[0][0] * delta[0] + j[0][1] * delta[1], j[1][0] * delta[0] + j[1][1] * delta[1]];
            let predicted = -(g(0) * delta[0] + g(1) * delta[1]) - 0.5 * (jd[0] * jd[0] + jd[1] * jd[1]);
            Ok(Some(Step { delta, predicted: Some(predicted) }))
        }

        fn damping_scale(&self) -> f64 {
            100.0
        }

        fn evaluate(&mut self, trial: &[f64], _delta: &[f64]) -> Result<Option<Self::Eval>, ()> {
            let r = residual(trial);
            let cost = 0.5 * (r[0] * r[0] + r[1] * r[1]);
            Ok((!self.broken).then_some((r, cost)))
        }

        fn accepted(&mut self, step: Accepted<'_, Self::Eval>) -> Option<String> {
            (step.to.1 < 1e-24 || step.decrease <= 1e-15 * step.from.1).then(|| "at the minimum".into())
        }

        fn restart(&mut self, _stop: &Stop, _at: &Self::Eval) -> bool {
            self.restarts += 1;
            self.broken && self.restarts == 1
        }
    }

    fn run(damping: Damping, counting: Counting, max_iterations: usize, broken: bool) -> (Outcome<(Vec<f64>, f64)>, usize) {
        let mut problem = Rosenbrock { broken, restarts: 0 };
        let x = vec![-1.2, 1.0];
        let r = residual(&x);
        let at = (r.clone(), 0.5 * (r[0] * r[0] + r[1] * r[1]));
        let options = Options { damping, acceptance: Acceptance::Decrease, counting, first_iteration: 1, max_iterations };
        let found = minimise(&mut problem, x, at, &options).unwrap();
        (found, problem.restarts)
    }

    const POLICIES: [Damping; 4] = [
        Damping::Marquardt { first: 1e-6, growth: 100.0, limit: 1e12, relax: Relax::Scale(0.1) },
        Damping::Marquardt { first: 1e-18, growth: 100.0, limit: 1e12, relax: Relax::Remembering { divisor: 10.0 } },
        Damping::Nielsen { initial: 1e-3, limit: 1e20 },
        Damping::Backtracking { shrink: 0.5, shortest: 1e-4 },
    ];

    /// Every policy walks Rosenbrock's valley to (1, 1) and says why it stopped (the problem asked
    /// once whether to restart).
    #[test]
    fn every_policy_reaches_the_minimum_and_says_so() {
        for damping in POLICIES {
            let (found, restarts) = run(damping, Counting::Steps, 200, false);
            assert_eq!(found.stop, Stop::Converged("at the minimum".into()), "{damping:?}");
            assert_eq!(restarts, 1, "{damping:?}");
            assert!((found.x[0] - 1.0).abs() < 1e-8 && (found.x[1] - 1.0).abs() < 1e-8, "{damping:?}: {:?}", found.x);
            assert!(found.iterations < 200, "{damping:?}: {}", found.iterations);
        }
    }

    /// The iteration limit, and no progress when no trial can be evaluated: under `Steps` the
    /// first iteration raises the damping to its limit; under `Trials` every raise is an iteration.
    #[test]
    fn the_limits_are_reported() {
        let (found, _) = run(POLICIES[0], Counting::Steps, 2, false);
        assert_eq!((found.stop, found.iterations), (Stop::IterationLimit, 2));
        let (found, _) = run(POLICIES[0], Counting::Steps, 100, true);
        // Restarted once (the damping back at 0), then no progress again.
        assert_eq!((found.stop, found.iterations), (Stop::NoProgress, 2));
        assert!(found.damping > 1e12, "{}", found.damping);
        let (found, _) = run(POLICIES[0], Counting::Trials, 100, true);
        // λ = 0, 1e-6, ×100 … until above 1e12: each rejection an iteration, twice.
        let (mut lambda, mut trials) = (0.0f64, 0);
        while lambda <= 1e12 {
            lambda = if lambda == 0.0 { 1e-6 } else { lambda * 100.0 };
            trials += 1;
        }
        assert_eq!((found.stop, found.iterations), (Stop::NoProgress, 2 * trials));
        let (found, _) = run(POLICIES[3], Counting::Trials, 100, true);
        assert_eq!((found.stop, found.iterations), (Stop::NoProgress, 2));
    }
}

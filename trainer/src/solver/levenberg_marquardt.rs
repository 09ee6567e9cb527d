//! Levenberg–Marquardt on E(P0) = ½ P0ᵀ K_lin P0 + 1/(2σ²) Σ |k1(x_i) − y_i|² (energy 16).
//!
//! Undamped Gauss–Newton first (the regulariser keeps each step well posed; damping only after a
//! failed step and not relaxed back to a level that failed until a step matches the model's
//! promise), starting from the linearised model's solution; while steps shrink fast, chord steps
//! reuse the last Jacobian's QR factors (a flow and two triangular applications instead of a
//! tangent and a factorisation). For large N the momenta are searched in K_lin's dominant
//! eigenspace (`SolverMethod`, `solver::subspace`), with damping that is a ball in momentum space.

use super::regulariser::{linear_response, regulariser_matrix};
use super::step::{DampingScale, StepFactor};
use super::subspace::{dominant_eigenspace, Declined, Eigenspace};
use crate::data::Measurements;
use crate::flow::tangent::{position_jacobian_in_pool, TangentAlong};
use crate::flow::ControlPoints;
use cbd_protocol::{f64_le_bytes, F64Slice, Integrator, JointKernel, Model, MomentumLaw, NominalModel, Normalisation, TaskKernel};
use faer::linalg::matmul::matmul;
use faer::{Accum, Mat, Par};

use std::time::Instant;

/// Everything that defines a CbD fit besides the data.
#[derive(Debug, Clone)]
pub struct CbdOptions {
    pub joint_kernel: JointKernel,
    pub task_kernel: TaskKernel,
    /// Noise level σ in internal units.
    pub sigma: f64,
    pub integrator: Integrator,
    pub law: MomentumLaw,
    pub normalisation: Normalisation,
    pub max_iterations: usize,
    /// Stop when an accepted step lowers the energy by less than this fraction.
    pub relative_tolerance: f64,
    /// Or when an exact Gauss–Newton step moves no training prediction by more than this, in
    /// internal units (normalised: the workspace's scale is about 1).
    pub prediction_tolerance: f64,
    /// Threads for the tangent's column chunks and the factorisations (results do not depend on it).
    pub threads: usize,
    /// Which momenta the solver searches over (see [`SolverMethod`]).
    pub method: SolverMethod,
    /// Print one line per iteration to stderr.
    pub verbose: bool,
}

impl CbdOptions {
    /// The paper's RR kernels (DESIGN.md §2) with our default scheme (Euler × 2) and σ = 1e-6.
    pub fn paper_rr() -> Self {
        CbdOptions {
            joint_kernel: JointKernel {
                gamma: 8.0,
                axes: heapless::Vec::from_slice(&[cbd_protocol::JointKernelAxis::Periodic { b: 1.0186 }; 2]).expect("2 axes"),
            },
            task_kernel: TaskKernel { width: 1.0270 },
            sigma: 1e-6,
            // Two Euler steps: a genuine (transported) flow that generalises best on the RR
            // benchmark; more stages add nonlinearity that the ill-conditioned momenta amplify.
            integrator: Integrator { method: cbd_protocol::IntegratorMethod::Euler, steps: 2 },
            // v = −K_V Jᵀ P: the linearisation is the GP with covariance K_lin (see MomentumLaw).
            law: MomentumLaw::Hamiltonian,
            normalisation: Normalisation::IDENTITY,
            max_iterations: 30,
            relative_tolerance: 1e-5,
            prediction_tolerance: 1e-10,
            threads: std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1).min(2),
            method: SolverMethod::Auto,
            verbose: false,
        }
    }
}

/// How the solver parametrises the N·m initial momenta.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SolverMethod {
    /// `Dense` up to `DENSE_MAX_UNKNOWNS` unknowns; above, `Eigenspace` when K_lin's dominant
    /// eigenspace is small next to N·m (it is for smooth kernels: its size does not grow with N),
    /// else `Dense`.
    Auto,
    /// All N·m momenta: exact Jacobians propagate N·m tangent directions, steps factor the
    /// 2Nm × Nm stacked matrix. O(N³) per iteration.
    Dense,
    /// P0 = S c with S the r dominant eigenvectors of K_lin (`solver::subspace`): Jacobians
    /// propagate r directions, steps factor an (Nm + r) × r matrix. O(N² r) per iteration.
    Eigenspace,
}

/// `SolverMethod::Auto` solves problems up to this many unknowns (N·m) densely.
pub const DENSE_MAX_UNKNOWNS: usize = 1024;
/// First probe block of the eigenspace (grown while the eigenspace fills it, up to 5/8 of N·m).
const FIRST_PROBES: usize = 1280;

/// The eigenspace the solver searches, or None for all momenta.
fn choose_basis(method: SolverMethod, k_reg: &Mat<f64>) -> Option<Eigenspace> {
    let dim = k_reg.nrows();
    match method {
        SolverMethod::Dense => None,
        // Forced: every probe the problem has, so the eigenspace is found whatever its size.
        SolverMethod::Eigenspace => dominant_eigenspace(k_reg, dim, FIXED_SPLIT).ok(),
        SolverMethod::Auto if dim <= DENSE_MAX_UNKNOWNS => None,
        SolverMethod::Auto => {
            let limit = dim * 5 / 8;
            let mut probes = FIRST_PROBES.min(limit);
            loop {
                match dominant_eigenspace(k_reg, probes, FIXED_SPLIT) {
                    Ok(e) => return Some(e),
                    Err(Declined::Full) if probes < limit => probes = (2 * probes).min(limit),
                    Err(_) => return None,
                }
            }
        }
    }
}

/// a · b on faer's fixed split.
fn product(a: &Mat<f64>, b: &Mat<f64>) -> Mat<f64> {
    let mut out = Mat::zeros(a.nrows(), b.ncols());
    matmul(out.as_mut(), Accum::Replace, a.as_ref(), b.as_ref(), 1.0, FIXED_SPLIT);
    out
}

#[derive(Debug, Clone, Copy, serde::Serialize)]
pub struct IterationLog {
    pub iteration: usize,
    pub energy: f64,
    pub regulariser: f64,
    /// RMS training error, user units.
    pub train_rms: f64,
    pub damping: f64,
    pub seconds: f64,
}

#[derive(Debug, Clone, serde::Serialize)]
pub struct FitReport {
    pub iterations: usize,
    pub converged: bool,
    pub stop_reason: String,
    pub log: Vec<IterationLog>,
    pub seconds: f64,
    pub seconds_flow: f64,
    pub seconds_tangent: f64,
    pub seconds_solve: f64,
    /// Exact Jacobians formed by the tangent flow (the first, at P0 = 0, is in closed form).
    pub tangents: usize,
    /// "dense" (all N·m momenta) or "eigenspace" (K_lin's dominant eigenspace).
    pub method: String,
    /// Unknowns of the search: N·m, or the eigenspace's dimension r.
    pub unknowns: usize,
    /// Finding the eigenspace (part of `seconds_solve`).
    pub seconds_basis: f64,
    /// Largest |runtime − trainer| at the training points relative to the largest |position|.
    pub max_runtime_trainer_diff: f64,
    /// How much the momenta cancel in the linear response: max_i Σ_j |K_ij P_j| / max_i |Σ_j K_ij P_j|
    /// (K = K_lin; NaN in the eigenspace). Rounding in the runtime is amplified by about this much:
    /// above ~1e5 the f32 runtime loses most of its 7 digits.
    pub cancellation: f64,
}

/// A fitted model: the blob and what it took.
#[derive(Debug, Clone)]
pub struct CbdFit {
    pub blob: Vec<u8>,
    /// N × m optimal initial momenta, internal units.
    pub momenta: Vec<f64>,
    /// k1 at the training points according to the trainer, user units.
    pub train_predictions: Vec<f64>,
    pub report: FitReport,
}

#[derive(Debug, Clone, PartialEq)]
pub enum FitError {
    TooFewMeasurements {
        got: usize,
        needed: usize,
    },
    DimensionMismatch {
        what: &'static str,
        expected: usize,
        found: usize,
    },
    /// The flow produced non-finite values even with the smallest step LM tried.
    Diverged {
        iteration: usize,
        damping: f64,
    },
    /// The damped normal equations could not be factored.
    Singular {
        iteration: usize,
        damping: f64,
    },
    Encode(String),
    /// The runtime could not load the blob or does not reproduce the training predictions.
    RuntimeMismatch(String),
}

impl std::fmt::Display for FitError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            FitError::TooFewMeasurements { got, needed } => write!(f, "too few measurements: {got}, need at least {needed}"),
            FitError::DimensionMismatch { what, expected, found } => write!(f, "{what}: expected {expected}, found {found}"),
            FitError::Diverged { iteration, damping } => write!(
                f,
                "the flow diverged at iteration {iteration} even with damping {damping:.1e}: the kernels are too wide or σ too small for these data"
            ),
            FitError::Singular { iteration, damping } => {
                write!(f, "the normal equations are singular at iteration {iteration} (damping {damping:.1e})")
            }
            FitError::Encode(e) => write!(f, "could not encode the model: {e}"),
            FitError::RuntimeMismatch(e) => write!(f, "the runtime does not reproduce the fit: {e}"),
        }
    }
}

impl std::error::Error for FitError {}

struct Evaluated {
    energy: f64,
    regulariser: f64,
    /// (k1 − y)/σ, N·m.
    residual: Vec<f64>,
    flow: crate::flow::PrimalFlow,
}

fn quad_form(k: &Mat<f64>, p: &[f64]) -> f64 {
    // (K p)_i summed over j in order, column by column (contiguous).
    let mut kp = vec![0.0; p.len()];
    for (j, pj) in p.iter().enumerate() {
        for (r, kij) in kp.iter_mut().zip(k.col(j).iter()) {
            *r += kij * pj;
        }
    }
    p.iter().zip(&kp).map(|(pi, r)| pi * r).sum()
}

/// The Gauss–Newton model of the energy after step `step` (to `trial`) with Jacobian `jac`:
/// ½ |r + J δ/σ|² + ½ trialᵀ K trial.
fn model_energy(jac: &Mat<f64>, k: &Mat<f64>, sigma: f64, residual: &[f64], step: &[f64], trial: &[f64]) -> f64 {
    let mut r: Vec<f64> = residual.to_vec();
    for (j, d) in step.iter().enumerate() {
        let scale = d / sigma;
        for (ri, jij) in r.iter_mut().zip(jac.col(j).iter()) {
            *ri += jij * scale;
        }
    }
    0.5 * r.iter().map(|v| v * v).sum::<f64>() + 0.5 * quad_form(k, trial)
}

/// max_i Σ_j |K_ij p_j| / max_i |Σ_j K_ij p_j| (see [`FitReport::cancellation`]).
fn cancellation_of(k: &Mat<f64>, p: &[f64]) -> f64 {
    let (mut sum, mut abs) = (vec![0.0; p.len()], vec![0.0; p.len()]);
    for (j, pj) in p.iter().enumerate() {
        for ((s, a), kij) in sum.iter_mut().zip(abs.iter_mut()).zip(k.col(j).iter()) {
            *s += kij * pj;
            *a += (kij * pj).abs();
        }
    }
    let top = |v: &[f64]| v.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    let moved = top(&sum);
    if moved > 0.0 {
        top(&abs) / moved
    } else {
        1.0
    }
}

/// Faer's work split for the factorisations: fixed, so the arithmetic (and the blob) does not
/// depend on how many threads the pool running it has (`Par::Seq` would round differently).
pub const FIXED_SPLIT: Par = Par::Rayon(match std::num::NonZeroUsize::new(2) {
    Some(n) => n,
    None => unreachable!(),
});
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

/// Fits the initial momenta to `data` (user units) on top of `nominal`, on `opts.threads` threads.
pub fn fit_cbd(nominal: &NominalModel, data: &Measurements, opts: &CbdOptions) -> Result<CbdFit, FitError> {
    super::allocator::keep_freed_memory();
    crate::flow::with_threads(opts.threads, || fit_in_pool(nominal, data, opts))
}

fn fit_in_pool(nominal: &NominalModel, data: &Measurements, opts: &CbdOptions) -> Result<CbdFit, FitError> {
    let start = Instant::now();
    let (n, m) = (nominal.n_joints(), nominal.task_dim());
    if data.n_joints != n {
        return Err(FitError::DimensionMismatch { what: "joints per measurement", expected: n, found: data.n_joints });
    }
    if data.task_dim != m {
        return Err(FitError::DimensionMismatch { what: "position coordinates per measurement", expected: m, found: data.task_dim });
    }
    if data.len() < 2 {
        return Err(FitError::TooFewMeasurements { got: data.len(), needed: 2 });
    }
    let norm = &opts.normalisation;
    let target: Vec<f64> =
        data.positions.chunks_exact(m).flat_map(|y| (0..m).map(move |c| (y[c] - norm.task_offset[c]) / norm.task_scale)).collect();
    let cp = ControlPoints::new(nominal, norm, data.joints.clone(), opts.joint_kernel.clone(), opts.task_kernel, opts.law, opts.integrator);
    let k_reg = regulariser_matrix(&cp);
    let sigma = opts.sigma;
    let (mut t_flow, mut t_tangent, mut t_solve) = (0.0, 0.0, 0.0);
    // One Euler step from P0: k1 = k0 + w(k0) − Dk0 v(x) is linear in P0, so the closed-form
    // Jacobian stays exact everywhere and no tangent is ever needed.
    let linear_scheme = opts.integrator.method == cbd_protocol::IntegratorMethod::Euler && opts.integrator.steps == 1;
    // Hamiltonian laws: the response at P0 = 0 is K_lin itself (see the closed-form start below).
    let response_is_k_lin = opts.law.joint_field_sign() < 0.0;
    let t0 = Instant::now();
    // The search space: all momenta (p are the momenta), or P0 = S p in K_lin's dominant eigenspace
    // (p are coordinates, the regulariser is Sᵀ K S).
    // One Euler step of a Hamiltonian law is solved in closed form, (K_lin + σ² I)⁻¹ r: one Cholesky
    // of all N·m momenta, exact, where an eigenspace would drop the directions between σ² and its cutoff.
    let closed_form = linear_scheme && response_is_k_lin && opts.method == SolverMethod::Auto;
    let basis = if closed_form { None } else { choose_basis(opts.method, &k_reg) };
    let seconds_basis = t0.elapsed().as_secs_f64();
    t_solve += seconds_basis;
    let (k_reg, method) = match &basis {
        Some(e) => (e.projected.clone(), "eigenspace"),
        None => (k_reg, "dense"),
    };
    let dim = k_reg.nrows();
    let damping_scale = if basis.is_some() { DampingScale::Uniform } else { DampingScale::PerParameter };
    let momenta_of = |p: &[f64]| -> Vec<f64> {
        match &basis {
            None => p.to_vec(),
            Some(e) => {
                let s = &e.basis;
                let mut out = vec![0.0; s.nrows()];
                for (j, pj) in p.iter().enumerate() {
                    for (o, v) in out.iter_mut().zip(s.col(j).iter()) {
                        *o += v * pj;
                    }
                }
                out
            }
        }
    };
    // Along the eigenspace, the first stage's P0-independent part is formed once (when the first
    // exact Jacobian is needed) and kept.
    let along: std::cell::OnceCell<TangentAlong> = std::cell::OnceCell::new();
    let exact_jacobian = |flow: &crate::flow::PrimalFlow| match &basis {
        None => position_jacobian_in_pool(&cp, flow),
        Some(e) => along.get_or_init(|| TangentAlong::new(&cp, e.basis.clone())).jacobian(&cp, flow),
    };
    if opts.verbose {
        eprintln!("solver: {method}, {dim} unknowns for {} momenta ({seconds_basis:.2} s to choose)", cp.len() * m);
    }

    let evaluate = |p: &[f64], t_flow: &mut f64| -> Option<Evaluated> {
        let t0 = Instant::now();
        let flow = cp.integrate(&momenta_of(p)).ok()?;
        *t_flow += t0.elapsed().as_secs_f64();
        let k1 = flow.positions(cp.dims);
        let residual: Vec<f64> = k1.iter().zip(&target).map(|(k, y)| (k - y) / sigma).collect();
        let regulariser = 0.5 * quad_form(&k_reg, p);
        let energy = regulariser + 0.5 * residual.iter().map(|r| r * r).sum::<f64>();
        energy.is_finite().then_some(Evaluated { energy, regulariser, residual, flow })
    };

    let mut p = vec![0.0; dim];
    let mut current = evaluate(&p, &mut t_flow).ok_or(FitError::Diverged { iteration: 0, damping: 0.0 })?;
    // Warm start: at P0 = 0 the model is linear, so the first Gauss–Newton step is the
    // linearised (kernel) model's solution; its Jacobian is known in closed form.
    let mut jac = match &basis {
        None => linear_response(&cp),
        Some(e) => product(&linear_response(&cp), &e.basis),
    };
    // Whether `jac` is the derivative at the current P0 (else it is an older one: a chord step).
    let mut jacobian_is_current = true;
    // The step's factorisation for the Jacobian in `jac` and damping λ, reused by chord steps.
    let mut factor: Option<StepFactor> = None;
    // The largest damping whose step failed with an exact Jacobian: relaxing stops above it.
    let mut failed_damping: Option<f64> = None;
    // Pure Gauss–Newton (the regulariser keeps it well posed); Marquardt damping only after a failed step.
    let mut damping = 0.0;
    let mut tangents = 0;
    let mut previous_decrease = f64::INFINITY;
    let mut chords_pay = true;
    let mut log = Vec::new();
    let rms = |r: &[f64]| (r.iter().map(|v| v * v).sum::<f64>() / (r.len() / m) as f64).sqrt() * sigma * norm.task_scale;
    let entry = |iteration: usize, e: &Evaluated, damping: f64| IterationLog {
        iteration,
        energy: e.energy,
        regulariser: e.regulariser,
        train_rms: rms(&e.residual),
        damping,
        seconds: start.elapsed().as_secs_f64(),
    };
    log.push(entry(0, &current, damping));
    // A bar on a terminal; plain lines when verbose output goes to a pipe or file.
    let progress = crate::report::progress::FitProgress::new(opts.max_iterations, !opts.verbose, "");
    progress.update(0, current.energy, rms(&current.residual));
    let print_lines = opts.verbose && !progress.is_visible();
    if print_lines {
        eprintln!("iter  0  energy {:.6e}  train rms {:.3e}", current.energy, rms(&current.residual));
    }
    let mut converged = false;
    let mut stop_reason = String::from("iteration limit");
    let mut iterations = 0;
    // Hamiltonian laws: the response at P0 = 0 is K_lin itself, so the linearised model's optimum
    // (the GP posterior mean) is P0 = (K_lin + σ² I)⁻¹ (y − k0) in closed form; in the eigenspace,
    // p_k = (Sᵀ(y − k0))_k / (λ_k + σ²). Exact for Euler × 1; the start of every other scheme.
    // Steps on the stacked least squares reach it only slowly when the evidence picks nearly
    // singular kernels (σ² far below the proximal term's scale).
    let mut first_iteration = 1;
    if response_is_k_lin {
        let t0 = Instant::now();
        let r: Vec<f64> = current.residual.iter().map(|v| -v * sigma).collect();
        let p_lin = match &basis {
            None => super::step::solve_regularised(&k_reg, sigma, &r, FIXED_SPLIT),
            Some(e) => Some(
                (0..dim)
                    .map(|k| e.basis.col(k).iter().zip(&r).map(|(s, r)| s * r).sum::<f64>() / (e.projected[(k, k)] + sigma * sigma))
                    .collect(),
            ),
        };
        t_solve += t0.elapsed().as_secs_f64();
        if let Some(e) = p_lin.as_ref().and_then(|p_lin| evaluate(p_lin, &mut t_flow)).filter(|e| e.energy < current.energy) {
            p = p_lin.unwrap_or_default();
            current = e;
            iterations = 1;
            first_iteration = 2;
            log.push(entry(1, &current, damping));
            progress.update(1, current.energy, rms(&current.residual));
            if print_lines {
                eprintln!(
                    "iter  1  energy {:.6e}  train rms {:.3e}  linearised model, closed form",
                    current.energy,
                    rms(&current.residual)
                );
            }
            if linear_scheme {
                converged = true;
                stop_reason = "closed form (the linearised model: Euler × 1)".into();
                first_iteration = usize::MAX;
            } else {
                let t0 = Instant::now();
                jac = exact_jacobian(&current.flow);
                t_tangent += t0.elapsed().as_secs_f64();
                tangents += 1;
            }
        }
    }
    for iteration in first_iteration..=opts.max_iterations {
        iterations = iteration;
        // Gauss–Newton step as a least-squares problem, never forming JᵀJ (which would square
        // the condition number): minimise |J δ/σ + r|² + (P + δ)ᵀ K (P + δ) + λ |D δ|²,
        // D² = diag(JᵀJ/σ² + K) (Marquardt scaling); see `step`.
        let mut accepted = None;
        let mut exact_step = jacobian_is_current;
        loop {
            let t0 = Instant::now();
            if factor.as_ref().is_none_or(|f| f.damping != damping) {
                factor = Some(
                    StepFactor::new(&jac, &k_reg, sigma, damping, damping_scale, PROXIMAL, FIXED_SPLIT)
                        .ok_or(FitError::Singular { iteration, damping })?,
                );
            }
            let step = factor.as_ref().map(|f| f.step(&k_reg, &current.residual, &p)).unwrap_or_default();
            t_solve += t0.elapsed().as_secs_f64();
            if step.iter().all(|v| v.is_finite()) {
                let trial: Vec<f64> = p.iter().zip(&step).map(|(v, d)| v + d).collect();
                if let Some(e) = evaluate(&trial, &mut t_flow).filter(|e| e.energy < current.energy) {
                    // The decrease the Gauss–Newton model promised, for the gain ratio below.
                    let predicted = current.energy - model_energy(&jac, &k_reg, sigma, &current.residual, &step, &trial);
                    accepted = Some((trial, e, predicted));
                    break;
                }
            }
            if !jacobian_is_current {
                // A chord step (older Jacobian) failed: take the exact Jacobian here instead of
                // damping, and no more chord steps (each failure costs a flow).
                chords_pay = false;
                let t0 = Instant::now();
                jac = exact_jacobian(&current.flow);
                t_tangent += t0.elapsed().as_secs_f64();
                tangents += 1;
                factor = None;
                jacobian_is_current = true;
                exact_step = true;
                continue;
            }
            failed_damping = Some(failed_damping.map_or(damping, |f| f.max(damping)));
            damping = if damping == 0.0 { FIRST_DAMPING } else { damping * DAMPING_GROWTH };
            if damping > 1e12 {
                break;
            }
        }
        let Some((trial, e, predicted)) = accepted else {
            if iteration == 1 {
                return Err(FitError::Diverged { iteration, damping });
            }
            converged = true;
            stop_reason = "no further decrease at any damping (converged to rounding)".into();
            break;
        };
        let decrease = current.energy - e.energy;
        let relative = decrease / current.energy;
        if decrease > 0.5 * predicted {
            // The model was good at this damping: lower levels that failed earlier, elsewhere in
            // the landscape, may be tried again (otherwise one early failure at a high level pins
            // the damping there for the rest of the fit).
            failed_damping = None;
        }
        // Largest change of a training prediction, internal (normalised) length units.
        let moved = sigma * current.residual.iter().zip(&e.residual).fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
        p = trial;
        current = e;
        jacobian_is_current = linear_scheme;
        log.push(entry(iteration, &current, damping));
        progress.update(iteration, current.energy, rms(&current.residual));
        if print_lines {
            eprintln!(
                "iter {iteration:2}  energy {:.6e}  train rms {:.3e}  damping {damping:.1e}  {}  {:.1} s",
                current.energy,
                rms(&current.residual),
                if exact_step { "exact J" } else { "chord" },
                start.elapsed().as_secs_f64()
            );
        }
        // Damping relaxes tenfold per success, back to pure Gauss–Newton, but not down to a level
        // that already failed (each new level costs a factorisation).
        damping = match damping / 10.0 {
            _ if damping == 0.0 => 0.0,
            relaxed if failed_damping.is_some_and(|f| relaxed <= f) => damping,
            relaxed if relaxed < FIRST_DAMPING => 0.0,
            relaxed => relaxed,
        };
        let small = relative < opts.relative_tolerance;
        if small && exact_step {
            // Converged: a step with the exact Jacobian gains (almost) nothing.
            converged = true;
            stop_reason = format!("relative energy decrease below {:.0e}", opts.relative_tolerance);
            break;
        }
        if exact_step && moved < opts.prediction_tolerance {
            // Settled: what is left of the energy's decrease is the regulariser in directions the
            // data do not resolve to working precision, which the (necessary) damping lets converge
            // only linearly. (An absolute length, not a multiple of σ: σ and the kernel amplitudes
            // can be rescaled together without changing the model.)
            converged = true;
            stop_reason = format!("no training prediction moved by {:.0e} (normalised units)", opts.prediction_tolerance);
            break;
        }
        // Keep the factorisation for a chord step while the energy's decrements shrink fast
        // (at least CHORD_CONTRACTION per step); otherwise form the exact Jacobian here.
        let chord = chords_pay && !small && decrease <= CHORD_CONTRACTION * previous_decrease;
        previous_decrease = decrease;
        if !linear_scheme && !chord {
            factor = None;
        }
        if !linear_scheme && !chord && iteration < opts.max_iterations {
            let t0 = Instant::now();
            jac = exact_jacobian(&current.flow);
            t_tangent += t0.elapsed().as_secs_f64();
            tangents += 1;
            jacobian_is_current = true;
        }
    }

    progress.finish(&stop_reason);
    let k1 = current.flow.positions(cp.dims);
    let train_predictions: Vec<f64> =
        k1.chunks_exact(m).flat_map(|k| (0..m).map(move |c| norm.task_offset[c] + norm.task_scale * k[c])).collect();
    let cancellation = if basis.is_none() { cancellation_of(&k_reg, &p) } else { f64::NAN };
    let p = momenta_of(&p);
    let (points, momenta) = (f64_le_bytes(&data.joints), f64_le_bytes(&p));
    let model = Model {
        nominal: nominal.clone(),
        normalisation: norm.clone(),
        joint_kernel: opts.joint_kernel.clone(),
        task_kernel: opts.task_kernel,
        integrator: opts.integrator,
        momentum_law: opts.law,
        sigma,
        n_points: data.len() as u32,
        points: F64Slice::from_le_bytes(&points),
        momenta: F64Slice::from_le_bytes(&momenta),
    };
    let blob = cbd_protocol::encode_to_vec(&model).map_err(|e| FitError::Encode(e.to_string()))?;
    // Never hand out a blob the runtime does not reproduce.
    let runtime = crate::predict::evaluate_blob(&blob, &data.joints).map_err(FitError::RuntimeMismatch)?;
    let scale = train_predictions.iter().fold(0.0f64, |s, v| s.max(v.abs())).max(f64::MIN_POSITIVE);
    let max_diff = runtime.iter().zip(&train_predictions).fold(0.0f64, |s, (a, b)| s.max((a - b).abs())) / scale;
    if !(max_diff <= 1e-12) {
        return Err(FitError::RuntimeMismatch(format!("largest relative difference at the training points is {max_diff:e} (limit 1e-12)")));
    }
    Ok(CbdFit {
        blob,
        momenta: p,
        train_predictions,
        report: FitReport {
            iterations,
            converged,
            stop_reason,
            log,
            seconds: start.elapsed().as_secs_f64(),
            seconds_flow: t_flow,
            seconds_tangent: t_tangent,
            seconds_solve: t_solve,
            tangents,
            method: method.into(),
            unknowns: dim,
            seconds_basis,
            max_runtime_trainer_diff: max_diff,
            cancellation,
        },
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::simulate::{configurations, rr, Sampling};

    fn rr_points(per_axis: usize) -> (ControlPoints, Measurements) {
        let data = rr::RealRr::default().measure(&configurations(Sampling::Grid { per_axis }, 2));
        let o = CbdOptions::paper_rr();
        let cp =
            ControlPoints::new(&rr::nominal(), &o.normalisation, data.joints.clone(), o.joint_kernel, o.task_kernel, o.law, o.integrator);
        (cp, data)
    }

    /// Momenta that nearly cancel: Σ|K P| / |Σ K P| is the amplification of rounding.
    #[test]
    fn cancellation_measures_how_much_the_momenta_cancel() {
        let k = Mat::from_fn(2, 2, |_, _| 1.0);
        assert_eq!(cancellation_of(&k, &[1.0, 2.0]), 1.0);
        let c = cancellation_of(&k, &[1e6, -1e6 + 1.0]);
        assert!((c - (2e6 - 1.0)).abs() < 1e-3, "{c}");
        assert_eq!(cancellation_of(&k, &[0.0, 0.0]), 1.0);
    }

    /// With every eigenvector kept (S square and orthogonal) the eigenspace method's steps are the
    /// dense method's, rotated: same momenta after each Gauss–Newton step, to rounding.
    #[test]
    fn eigenspace_steps_match_dense_steps_when_nothing_is_cut() {
        let (cp, data) = rr_points(4);
        let k = regulariser_matrix(&cp);
        let e = choose_basis(SolverMethod::Eigenspace, &k).expect("eigenspace");
        assert_eq!(e.values.len(), k.nrows(), "the test needs the whole space (no eigenvalue below the cutoff)");
        for iterations in [1, 2] {
            let mut opts = CbdOptions::paper_rr();
            opts.sigma = 1e-3;
            opts.max_iterations = iterations;
            opts.method = SolverMethod::Dense;
            let dense = fit_cbd(&rr::nominal(), &data, &opts).unwrap();
            opts.method = SolverMethod::Eigenspace;
            let sub = fit_cbd(&rr::nominal(), &data, &opts).unwrap();
            assert_eq!((dense.report.method.as_str(), sub.report.method.as_str()), ("dense", "eigenspace"));
            let scale = dense.momenta.iter().fold(0.0f64, |s, v| s.max(v.abs()));
            let worst = dense.momenta.iter().zip(&sub.momenta).fold(0.0f64, |w, (a, b)| w.max((a - b).abs()));
            assert!(worst < 1e-9 * scale, "{iterations} iterations: {worst:e} (scale {scale:e})");
        }
    }

    /// Auto: dense up to DENSE_MAX_UNKNOWNS unknowns; above, the eigenspace, whose size does not
    /// grow with N on the RR benchmark (about 850 directions at N = 1024, see `solver::subspace`).
    #[test]
    fn automatic_choice_is_dense_for_small_and_eigenspace_for_large_problems() {
        let (small, _) = rr_points(16);
        assert!(small.len() * 2 <= DENSE_MAX_UNKNOWNS);
        assert!(choose_basis(SolverMethod::Auto, &regulariser_matrix(&small)).is_none());
        let (large, _) = rr_points(32);
        let e = choose_basis(SolverMethod::Auto, &regulariser_matrix(&large)).expect("eigenspace at N = 1024");
        let r = e.values.len();
        assert!((700..1000).contains(&r), "eigenspace dimension {r}");
        assert_eq!((e.basis.nrows(), e.basis.ncols()), (2048, r));
        assert!(choose_basis(SolverMethod::Dense, &regulariser_matrix(&large)).is_none());
    }
}

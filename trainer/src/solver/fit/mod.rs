//! CbD's fit: the momenta (or the expansion's weights) minimising
//! E(P0) = ½ P0ᵀ K_lin P0 + 1/(2σ²) Σ |k1(x_i) − y_i|² (energy 16). Euler × 1 with the Hamiltonian
//! law is linear and solved in closed form (docs/DESIGN.md §3); every other scheme starts there and
//! iterates Levenberg–Marquardt (`iterate`).
//!
//! Undamped Gauss–Newton first (the regulariser keeps each step well posed; damping only after a
//! failed step and not relaxed back to a level that failed until a step matches the model's
//! promise), starting from the linearised model's solution; while steps shrink fast, chord steps
//! reuse the last Jacobian's QR factors (a flow and two triangular applications instead of a
//! tangent and a factorisation). For large N the momenta are searched in K_lin's dominant
//! eigenspace (`SolverMethod`, `solver::subspace`), with damping that is a ball in momentum space.

mod configuration;
pub use configuration::{predict_with_configuration, solve_with_configuration};
mod encode;
mod flow_expansion;
mod hyperparameters;
mod iterate;
pub(crate) mod problem;
mod search_space;

use super::regulariser::regulariser_matrix;
use crate::data::Measurements;
use crate::flow::ControlPoints;
use cbd_protocol::{Integrator, JointKernel, MomentumLaw, NominalModel, Normalisation, TaskKernel};
pub use hyperparameters::FlowHyperparameters;
use problem::{cancellation_of, Problem};
use search_space::SearchSpace;

use std::time::Instant;

/// Everything that defines a CbD fit besides the data: the model (kernels, σ, scheme,
/// normalisation) and how the solver runs ([`SolverSettings`], the pipeline's `Settings` hands its
/// own over whole: `calibrate::options_for`).
#[derive(Debug, Clone)]
pub struct CbdOptions {
    pub joint_kernel: JointKernel,
    pub task_kernel: TaskKernel,
    /// Noise level σ in internal units.
    pub sigma: f64,
    pub integrator: Integrator,
    pub normalisation: Normalisation,
    pub solver: SolverSettings,
    /// The noise σ per coordinate in the data's unit the blob records (format 7; the pipeline sets
    /// it, `calibrate::options_for`); `None`: not recorded.
    pub noise_sigma: Option<f64>,
    /// The configuration-dependent task term (docs/DESIGN.md §16, γ_C normalised like the joint
    /// kernel's γ); the fit is then Euler × 1's closed form in the kernel form only.
    pub configuration_kernel: Option<cbd_protocol::ConfigurationKernel>,
}

/// How a fit runs, besides its model: one struct that the pipeline's `Settings` (what a user sets,
/// `cbd`'s solver arguments) and [`CbdOptions`] both hold, so that no field is copied by hand.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SolverSettings {
    /// The momentum law; the Hamiltonian by default (v = −K_V Jᵀ P: the linearisation is the GP
    /// with covariance K_lin, see `MomentumLaw`).
    pub law: MomentumLaw,
    pub max_iterations: usize,
    /// Stop when an accepted step lowers the energy by less than this fraction.
    pub relative_tolerance: f64,
    /// Or when an exact Gauss–Newton step moves no training prediction by more than this, in
    /// internal units (normalised: the workspace's scale is about 1).
    pub prediction_tolerance: f64,
    /// Threads for the tangent's column chunks and the factorisations (results do not depend on
    /// it); up to two by default.
    pub threads: usize,
    /// Which momenta the solver searches over (see [`SolverMethod`]).
    pub method: SolverMethod,
    /// Print one line per iteration to stderr.
    pub verbose: bool,
    /// Whether the blob also carries the fields in the kernels' own expansion (docs/DESIGN.md §11);
    /// `Auto` by default ([`CbdOptions::new`]: the momenta).
    pub representation: crate::expansion::Representation,
    /// Bytes the kernel form's (N·m)² matrices may take ([`kernel_form_bytes`]); a fit that would
    /// need more is refused (`FitError::TooLarge`) before allocating. `None`: unchecked.
    pub memory_budget: Option<f64>,
}

impl Default for SolverSettings {
    /// The Hamiltonian law, Levenberg–Marquardt's stopping rules, up to 30 iterations on up to two
    /// threads, the method chosen by size, the representation chosen by cost, no memory budget.
    fn default() -> Self {
        SolverSettings {
            law: MomentumLaw::Hamiltonian,
            max_iterations: 30,
            relative_tolerance: 1e-5,
            prediction_tolerance: 1e-10,
            threads: std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1).min(2),
            method: SolverMethod::Auto,
            verbose: false,
            representation: crate::expansion::Representation::Auto,
            memory_budget: None,
        }
    }
}

impl CbdOptions {
    /// A fit with the given kernels and noise (internal units), scheme and normalisation, and the
    /// solver's defaults ([`SolverSettings::default`]) but the fields as momenta (the pipeline,
    /// `calibrate::options_for`, sets the user's representation).
    pub fn new(hyperparameters: FlowHyperparameters, integrator: Integrator, normalisation: Normalisation) -> Self {
        let FlowHyperparameters { joint_kernel, task_kernel, sigma, configuration_kernel } = hyperparameters;
        CbdOptions {
            joint_kernel,
            task_kernel,
            sigma,
            integrator,
            normalisation,
            solver: SolverSettings { representation: crate::expansion::Representation::Kernel, ..SolverSettings::default() },
            noise_sigma: None,
            configuration_kernel,
        }
    }

    /// The paper's RR kernels (docs/DESIGN.md §6) with the paper's scheme here (Euler × 2) and
    /// σ = 1e-6, written as momenta (the kernel form), in the paper's units (no normalisation).
    pub fn paper_rr() -> Self {
        // Two Euler steps: a genuine (transported) flow that generalises best on the RR
        // benchmark; more stages add nonlinearity that the ill-conditioned momenta amplify.
        let integrator = Integrator { method: cbd_protocol::IntegratorMethod::Euler, steps: 2 };
        let hyperparameters = FlowHyperparameters {
            joint_kernel: cbd_protocol::paper_rr::joint_kernel(),
            task_kernel: cbd_protocol::paper_rr::task_kernel(),
            sigma: 1e-6,
            configuration_kernel: None,
        };
        CbdOptions::new(hyperparameters, integrator, Normalisation::IDENTITY)
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

/// Copies of the (N·m)² momentum-space matrix a kernel-form fit holds at its peak (K_lin, its
/// Cholesky factor, the tangent and a work copy): 2.0 GB measured at N = 4096, m = 2 is 3.7 copies.
const KERNEL_FORM_MATRIX_COPIES: f64 = 4.0;

/// Estimated peak bytes of a kernel-form fit of `unknowns` = N·m momenta.
pub fn kernel_form_bytes(unknowns: usize) -> f64 {
    KERNEL_FORM_MATRIX_COPIES * (unknowns as f64).powi(2) * 8.0
}

/// `SolverMethod::Auto` solves problems up to this many unknowns (N·m) densely.
pub const DENSE_MAX_UNKNOWNS: usize = 1024;
/// The linear scheme's closed form (one dense Cholesky of all N·m momenta) up to this many unknowns;
/// beyond, the expansion's weights when it serves (O(N m r²), no (N m)² matrix), else the kernel form.
pub const CLOSED_FORM_MAX_UNKNOWNS: usize = 8192;
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
    /// above ~1e5 the f32 runtime loses most of its 7 digits. Of the representation the runtime
    /// evaluates: the expansion's terms A_ij w_j when the blob carries one.
    pub cancellation: f64,
    /// The momenta's cancellation (the kernel form, the blob's reference), whichever is evaluated.
    pub kernel_cancellation: f64,
    /// "kernel" (points and momenta) or "expansion" (the fields in the kernels' own basis, §11).
    pub representation: String,
    /// The expansion the blob carries.
    pub expansion: Option<ExpansionReport>,
    /// Why the blob has no expansion (the scheme, the kernels' length, the choice), when it has none.
    pub expansion_declined: Option<String>,
}

/// What the expansion is (docs/DESIGN.md §11).
#[derive(Debug, Clone, serde::Serialize)]
pub struct ExpansionReport {
    pub weights: usize,
    pub joint_features: usize,
    pub task_features: usize,
    /// The prior weight each kernel's expansion drops, relative to its total.
    pub tolerance: f64,
    /// Task-space radius (internal units) the task expansion covers.
    pub task_radius: f64,
    /// Largest |weight| in prior standard deviations.
    pub largest_whitened_weight: f64,
    /// Largest |expansion − kernel form| at the training points, user units (truncation and the
    /// momenta's rounding together).
    pub kernel_form_difference: f64,
}

impl ExpansionReport {
    pub fn of(e: &crate::expansion::ExpansionFit, kernel_form_difference: f64) -> Self {
        ExpansionReport {
            weights: e.len(),
            joint_features: e.joint.len(),
            task_features: e.task.len(),
            tolerance: e.tolerance,
            task_radius: e.task_radius,
            largest_whitened_weight: e.largest_whitened_weight,
            kernel_form_difference,
        }
    }
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
    /// The protocol refused to encode the model.
    Encode(cbd_protocol::EncodeError),
    /// The kernel form's matrices would need more memory than the budget (bytes).
    TooLarge {
        unknowns: usize,
        /// Coordinates per measurement (the unknowns are rows × this).
        task_dim: usize,
        need: f64,
        budget: f64,
        /// Why the expansion, which needs no (N·m)² matrix, could not serve.
        expansion_declined: String,
    },
    /// The runtime could not load the blob or does not reproduce the training predictions.
    RuntimeMismatch(String),
    /// The configuration field asked of a scheme or law the blob format does not evaluate it with.
    Configuration(String),
    /// The expansion's least-squares problem does not fit in the memory this process may use.
    /// An error, not a fall-back to the kernel form: the blob never depends on the memory limit.
    Memory(String),
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
            FitError::TooLarge { unknowns, task_dim, need, budget, expansion_declined } => {
                // The rows whose kernel form fits the budget: a remedy only when a few do.
                let rows = ((budget / kernel_form_bytes(1)).sqrt() / (*task_dim).max(1) as f64).floor() as usize;
                let remedy = match rows >= 3 {
                    true => format!("at most {rows} rows fit: fit fewer rows (--max-rows)"),
                    false => "raise the memory limit".to_string(),
                };
                write!(
                    f,
                    "the kernel form of {unknowns} momenta needs about {}, more than the {} this process may use (the expansion, which would not, declined: {expansion_declined}); {remedy}",
                    crate::memory::gigabytes(*need),
                    crate::memory::gigabytes(*budget)
                )
            }
            FitError::RuntimeMismatch(e) => write!(f, "the runtime does not reproduce the fit: {e}"),
            FitError::Configuration(why) => write!(f, "{why}"),
            FitError::Memory(why) => write!(f, "{why}: raise the memory limit, or fit the kernel form (--representation kernel)"),
        }
    }
}

impl std::error::Error for FitError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            FitError::Encode(e) => Some(e),
            _ => None,
        }
    }
}

impl From<FitError> for crate::Error {
    fn from(e: FitError) -> crate::Error {
        crate::Error::stage("fit", e)
    }
}

/// Fits the initial momenta to `data` (user units) on top of `nominal`, on `opts.solver.threads` threads.
pub fn fit_cbd(nominal: &NominalModel, data: &Measurements, opts: &CbdOptions) -> Result<CbdFit, FitError> {
    crate::flow::with_threads(opts.solver.threads, || fit_in_pool(nominal, data, opts))
}

fn fit_in_pool(nominal: &NominalModel, data: &Measurements, opts: &CbdOptions) -> Result<CbdFit, FitError> {
    let start = Instant::now();
    check_shapes(nominal, data)?;
    let m = nominal.task_dim();
    let norm = &opts.normalisation;
    let (cp, target) = control_points_and_target(nominal, data, opts);
    // With the configuration field: Euler × 1's closed form in the kernel form only (§16).
    if let Some(c) = &opts.configuration_kernel {
        return configuration::fit(nominal, data, opts, &cp, c, &target, start);
    }
    // One Euler step from P0: k1 = k0 + w(k0) − Dk0 v(x) is linear in P0, so the closed-form
    // Jacobian stays exact everywhere and no tangent is ever needed.
    let linear_scheme = opts.integrator.method == cbd_protocol::IntegratorMethod::Euler && opts.integrator.steps == 1;
    // One Euler step of a Hamiltonian law is solved in closed form, (K_lin + σ² I)⁻¹ r: one Cholesky
    // of all N·m momenta, exact, where an eigenspace would drop the directions between σ² and its cutoff.
    let closed_form = linear_scheme && opts.solver.law.joint_field_sign() < 0.0 && opts.solver.method == SolverMethod::Auto;
    // Multi-step schemes in weight space when the expansion serves (flow_expansion), else the
    // kernel form's iterations below.
    let mut declined_flow = None;
    if !linear_scheme || (closed_form && cp.len() * m > CLOSED_FORM_MAX_UNKNOWNS) {
        let inputs = flow_expansion::ExpansionInputs { nominal, data, opts, cp: &cp, target: &target, start };
        match flow_expansion::fit(inputs, linear_scheme)? {
            Ok(fit) => return Ok(fit),
            Err(why) => declined_flow = Some(why.to_string()),
        }
    }
    let unknowns = cp.len() * m;
    if let Some(budget) = opts.solver.memory_budget.filter(|b| kernel_form_bytes(unknowns) > *b) {
        let expansion_declined = declined_flow.clone().unwrap_or_else(|| "not tried for this scheme and size".into());
        return Err(FitError::TooLarge { unknowns, task_dim: m, need: kernel_form_bytes(unknowns), budget, expansion_declined });
    }
    crate::memory::note_need(kernel_form_bytes(unknowns), unknowns);
    let t0 = Instant::now();
    let space = SearchSpace::new(opts.solver.method, regulariser_matrix(&cp), closed_form);
    let seconds_basis = t0.elapsed().as_secs_f64();
    let (method, dim) = (space.method(), space.dim());
    if opts.solver.verbose {
        errln!("solver: {method}, {dim} unknowns for {} momenta ({seconds_basis:.2} s to choose)", cp.len() * m);
    }
    let problem = Problem::new(&cp, target.clone(), opts.sigma, space);
    problem.timers.solve.set(seconds_basis);
    let mut recorder = iterate::Recorder::new(opts, start);
    let outcome = iterate::minimise(&problem, opts, linear_scheme, &mut recorder)?;
    recorder.finish(&outcome.stop_reason);

    let user = |k: &[f64]| -> Vec<f64> { k.chunks_exact(m).flat_map(|k| (0..m).map(move |c| norm.position_to_user(c, k[c]))).collect() };
    let kernel_predictions = user(&outcome.current.flow.positions(cp.dims));
    let kernel_cancellation = if problem.space.basis.is_none() { cancellation_of(&problem.space.k_reg, &outcome.p) } else { f64::NAN };
    let momenta = problem.space.momenta_of(&outcome.p);
    let (expansion, expansion_declined) = match declined_flow {
        Some(why) => (None, Some(why)),
        None => choose_expansion(&cp, opts, &target, linear_scheme, kernel_cancellation)?,
    };
    let (train_predictions, cancellation, expansion_report) = match &expansion {
        Some(e) => {
            let predictions = user(&e.positions);
            let kernel_form_difference = predictions.iter().zip(&kernel_predictions).fold(0.0f64, |s, (a, b)| s.max((a - b).abs()));
            (predictions, e.cancellation, Some(ExpansionReport::of(e, kernel_form_difference)))
        }
        None => (kernel_predictions, kernel_cancellation, None),
    };
    if opts.solver.verbose {
        match &expansion_report {
            Some(e) => errln!(
                "expansion: {} weights ({} joint, {} task functions, tolerance {:.0e}), cancellation {:.1e} (momenta {:.1e})",
                e.weights,
                e.joint_features,
                e.task_features,
                e.tolerance,
                cancellation,
                kernel_cancellation
            ),
            None => errln!("expansion: none ({})", expansion_declined.as_deref().unwrap_or("")),
        }
    }
    let (blob, max_runtime_trainer_diff) = encode::encode_checked(nominal, data, opts, &momenta, expansion.as_ref(), &train_predictions)?;
    let timers = &problem.timers;
    Ok(CbdFit {
        blob,
        momenta,
        train_predictions,
        report: FitReport {
            iterations: outcome.iterations,
            converged: outcome.converged,
            stop_reason: outcome.stop_reason,
            log: recorder.log,
            seconds: start.elapsed().as_secs_f64(),
            seconds_flow: timers.flow.get(),
            seconds_tangent: timers.tangent.get(),
            seconds_solve: timers.solve.get(),
            tangents: timers.tangents.get(),
            method: method.into(),
            unknowns: dim,
            seconds_basis,
            max_runtime_trainer_diff,
            cancellation,
            kernel_cancellation,
            representation: if expansion.is_some() { "expansion" } else { "kernel" }.into(),
            expansion: expansion_report,
            expansion_declined,
        },
    })
}

/// The control points of `data` for `opts`' kernels and the measured positions (internal units).
pub(crate) fn control_points_and_target(nominal: &NominalModel, data: &Measurements, opts: &CbdOptions) -> (ControlPoints, Vec<f64>) {
    let (m, norm) = (nominal.task_dim(), &opts.normalisation);
    let target: Vec<f64> = data.positions.chunks_exact(m).flat_map(|y| (0..m).map(move |c| norm.position_to_internal(c, y[c]))).collect();
    let cp = ControlPoints::new(
        nominal,
        norm,
        data.joints.clone(),
        opts.joint_kernel.clone(),
        opts.task_kernel,
        opts.solver.law,
        opts.integrator,
    );
    (cp, target)
}

/// The expansion the blob carries (docs/DESIGN.md §11), or why none: only the linear scheme
/// (Euler × 1, Hamiltonian law) has one here; `Auto` takes it when it has no more weights than
/// there are momenta, or when the momenta cancel beyond [`crate::expansion::CANCELLATION_LIMIT`].
fn choose_expansion(
    cp: &ControlPoints,
    opts: &CbdOptions,
    target: &[f64],
    linear_scheme: bool,
    kernel_cancellation: f64,
) -> Result<(Option<crate::expansion::ExpansionFit>, Option<String>), FitError> {
    use crate::expansion::{fit_linear_in, linear_basis, Declined, Representation, CANCELLATION_LIMIT};
    if opts.solver.representation == Representation::Kernel {
        return Ok((None, Some("kernel form requested".into())));
    }
    if !linear_scheme || opts.solver.law.joint_field_sign() > 0.0 {
        return Ok((None, Some("only the Hamiltonian laws have the Gaussian-process prior the expansion uses".into())));
    }
    let momenta = cp.len() * cp.dims.m;
    let basis = match linear_basis(cp, &opts.joint_kernel, &opts.task_kernel, opts.sigma) {
        Ok(b) => b,
        Err(why) => return Ok((None, Some(why.to_string()))),
    };
    // Its length decides before the solve (a QR of N m × W): a longer expansion is kept only when
    // the momenta cancel or it was asked for.
    let weights = basis.weights(cp.dims.n, cp.dims.m);
    if opts.solver.representation == Representation::Auto && weights > momenta && !(kernel_cancellation > CANCELLATION_LIMIT) {
        return Ok((
            None,
            Some(format!(
                "the expansion has {weights} weights, more than the {momenta} momenta, which do not cancel ({kernel_cancellation:.1e})"
            )),
        ));
    }
    Ok(match fit_linear_in(cp, basis, &opts.joint_kernel, &opts.task_kernel, opts.sigma, target) {
        Ok(e) => (Some(e), None),
        Err(Declined::Memory(why)) => return Err(FitError::Memory(why)),
        Err(why) => (None, Some(why.to_string())),
    })
}

/// The data's shape against the nominal model's, and enough rows to fit.
fn check_shapes(nominal: &NominalModel, data: &Measurements) -> Result<(), FitError> {
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
    Ok(())
}

#[cfg(test)]
mod tests;

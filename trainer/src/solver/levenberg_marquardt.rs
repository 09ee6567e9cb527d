//! Levenberg–Marquardt on E(P0) = ½ P0ᵀ K_lin P0 + 1/(2σ²) Σ |k1(x_i) − y_i|² (energy 16).

use super::regulariser::{linear_response, regulariser_matrix};
use crate::data::Measurements;
use crate::flow::tangent::position_jacobian;
use crate::flow::ControlPoints;
use cbd_protocol::{f64_le_bytes, F64Slice, Integrator, JointKernel, Model, MomentumLaw, NominalModel, Normalisation, TaskKernel};
use faer::linalg::matmul::matmul;
use faer::linalg::solvers::SolveLstsq;
use faer::{Accum, Mat, Par, Side};

/// Lᵀ with K = L Lᵀ. Kernel matrices of distinct points are positive definite but can be
/// numerically singular; a jitter of 1e-13 · mean diagonal, grown tenfold until the factorisation
/// succeeds, keeps the regulariser a norm.
fn regulariser_factor(k: &Mat<f64>) -> Result<Mat<f64>, FitError> {
    let dim = k.nrows();
    let mean_diag = (0..dim).map(|i| k[(i, i)]).sum::<f64>() / dim as f64;
    let mut jitter = 1e-13 * mean_diag;
    for _ in 0..8 {
        let mut kj = k.clone();
        for i in 0..dim {
            kj[(i, i)] += jitter;
        }
        if let Ok(llt) = kj.llt(Side::Lower) {
            return Ok(llt.L().transpose().to_owned());
        }
        jitter *= 10.0;
    }
    Err(FitError::Singular { iteration: 0, damping: jitter })
}
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
    /// Threads for the tangent (results do not depend on it).
    pub threads: usize,
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
            law: MomentumLaw::WithDivergence,
            normalisation: Normalisation::IDENTITY,
            max_iterations: 30,
            relative_tolerance: 1e-5,
            threads: std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1).min(2),
            verbose: false,
        }
    }
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
    /// Largest |runtime − trainer| at the training points relative to the largest |position|.
    pub max_runtime_trainer_diff: f64,
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
    let mut s = 0.0;
    for (i, pi) in p.iter().enumerate() {
        let mut r = 0.0;
        for (j, pj) in p.iter().enumerate() {
            r += k[(i, j)] * pj;
        }
        s += pi * r;
    }
    s
}

/// Fits the initial momenta to `data` (user units) on top of `nominal`.
pub fn fit_cbd(nominal: &NominalModel, data: &Measurements, opts: &CbdOptions) -> Result<CbdFit, FitError> {
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
    let dim = cp.len() * m;
    let k_reg = regulariser_matrix(&cp);
    let chol_t = regulariser_factor(&k_reg)?;
    let sigma = opts.sigma;
    let (mut t_flow, mut t_tangent, mut t_solve) = (0.0, 0.0, 0.0);

    let evaluate = |p: &[f64], t_flow: &mut f64| -> Option<Evaluated> {
        let t0 = Instant::now();
        let flow = cp.integrate(p).ok()?;
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
    let mut jac = linear_response(&cp);
    let mut damping = 1e-6;
    let mut log = Vec::new();
    let rms = |r: &[f64]| (r.iter().map(|v| v * v).sum::<f64>() / (r.len() / m) as f64).sqrt() * sigma * norm.task_scale;
    log.push(IterationLog {
        iteration: 0,
        energy: current.energy,
        regulariser: current.regulariser,
        train_rms: rms(&current.residual),
        damping,
        seconds: start.elapsed().as_secs_f64(),
    });
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
    let mut small_steps = 0;
    for iteration in 1..=opts.max_iterations {
        iterations = iteration;
        // Gauss–Newton step as a least-squares problem, never forming JᵀJ (which would square
        // the condition number): minimise |J δ/σ + r|² + |Lᵀ (P + δ)|² + λ |D δ|², K = L Lᵀ,
        // D² = diag(JᵀJ/σ² + K) (Marquardt scaling).
        let t0 = Instant::now();
        let lt_p = {
            let pm = Mat::from_fn(dim, 1, |i, _| p[i]);
            let mut out = Mat::zeros(dim, 1);
            matmul(out.as_mut(), Accum::Replace, chol_t.as_ref(), pm.as_ref(), 1.0, Par::Seq);
            out
        };
        let scaling: Vec<f64> =
            (0..dim).map(|c| ((0..dim).map(|r| (jac[(r, c)] / sigma).powi(2)).sum::<f64>() + k_reg[(c, c)]).sqrt().max(1e-300)).collect();
        t_solve += t0.elapsed().as_secs_f64();
        let mut accepted = None;
        while damping < 1e12 {
            let t0 = Instant::now();
            let sqrt_damping = damping.sqrt();
            let a = Mat::from_fn(3 * dim, dim, |r, c| {
                if r < dim {
                    jac[(r, c)] / sigma
                } else if r < 2 * dim {
                    chol_t[(r - dim, c)]
                } else if r - 2 * dim == c {
                    sqrt_damping * scaling[c]
                } else {
                    0.0
                }
            });
            let b = Mat::from_fn(3 * dim, 1, |r, _| {
                if r < dim {
                    -current.residual[r]
                } else if r < 2 * dim {
                    -lt_p[(r - dim, 0)]
                } else {
                    0.0
                }
            });
            let solution = a.qr().solve_lstsq(&b);
            t_solve += t0.elapsed().as_secs_f64();
            if !(0..dim).all(|i| solution[(i, 0)].is_finite()) {
                damping *= 10.0;
                continue;
            }
            let trial: Vec<f64> = p.iter().enumerate().map(|(i, v)| v + solution[(i, 0)]).collect();
            match evaluate(&trial, &mut t_flow) {
                Some(e) if e.energy < current.energy => {
                    accepted = Some((trial, e));
                    break;
                }
                _ => damping *= 4.0,
            }
        }
        let Some((trial, e)) = accepted else {
            if iteration == 1 {
                return Err(FitError::Diverged { iteration, damping });
            }
            converged = true;
            stop_reason = "no further decrease at any damping (converged to rounding)".into();
            break;
        };
        let decrease = (current.energy - e.energy) / current.energy;
        p = trial;
        current = e;
        damping = (damping / 10.0).max(1e-30);
        log.push(IterationLog {
            iteration,
            energy: current.energy,
            regulariser: current.regulariser,
            train_rms: rms(&current.residual),
            damping,
            seconds: start.elapsed().as_secs_f64(),
        });
        progress.update(iteration, current.energy, rms(&current.residual));
        if print_lines {
            eprintln!(
                "iter {iteration:2}  energy {:.6e}  train rms {:.3e}  damping {damping:.1e}  {:.1} s",
                current.energy,
                rms(&current.residual),
                start.elapsed().as_secs_f64()
            );
        }
        if decrease < opts.relative_tolerance {
            small_steps += 1;
            if small_steps >= 2 {
                converged = true;
                stop_reason = format!("relative energy decrease below {:.0e}", opts.relative_tolerance);
                break;
            }
        } else {
            small_steps = 0;
        }
        // One Euler step from P0: k1 = k0 + w(k0) − Dk0 v(x) is linear in P0, so the closed-form
        // Jacobian stays exact and no tangent is needed.
        let linear_scheme = opts.integrator.method == cbd_protocol::IntegratorMethod::Euler && opts.integrator.steps == 1;
        if iteration < opts.max_iterations && !linear_scheme {
            let t0 = Instant::now();
            jac = position_jacobian(&cp, &current.flow, opts.threads);
            t_tangent += t0.elapsed().as_secs_f64();
        }
    }

    progress.finish(&stop_reason);
    let k1 = current.flow.positions(cp.dims);
    let train_predictions: Vec<f64> =
        k1.chunks_exact(m).flat_map(|k| (0..m).map(move |c| norm.task_offset[c] + norm.task_scale * k[c])).collect();
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
            max_runtime_trainer_diff: max_diff,
        },
    })
}

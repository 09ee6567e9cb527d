//! CbD's fields in the kernels' own basis (docs/DESIGN.md §11, issue 25): the evidence prefers very
//! flat kernels, and a flat kernel's field written as momenta at the N measured points cancels to
//! 1 part in 1e5–1e12. The same field is a short series in the kernel's own expansion — Fourier
//! modes with Bessel weights per periodic joint, the Gaussian's power series per task coordinate —
//! whose weights can be solved directly, with every digit kept.
//!
//! weights (per-axis shares and variances) → basis (which functions) → solve (the weights).

pub mod basis;
pub mod flow_fit;
pub mod solve;

use crate::axis_forms::joint_series;
use crate::flow::ControlPoints;
use basis::{truncate, AxisSeries, Basis};
use cbd_protocol::{JointKernel, TaskKernel};
use solve::{apply, design, posterior_weights, prior_variances, LinearProblem};

/// Which representation the blob's evaluation uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum Representation {
    /// The expansion when it is cheaper than the momenta, or when the momenta cancel (below).
    #[default]
    Auto,
    /// Points and momenta only (formats 2–4).
    Kernel,
    /// The expansion whenever the kernels have one within the limits.
    Expansion,
}

/// `Auto` takes the expansion over cheaper momenta when the momenta cancel beyond this
/// (`FitReport::cancellation`): the f32 runtime would keep fewer than ~3 of its 7 digits.
pub const CANCELLATION_LIMIT: f64 = 1e4;
/// Weights above which the expansion is never used (the fit's QR is O(W² (N m + W))).
pub const MAX_WEIGHTS: usize = 8192;

/// Most weights (over all stages) a multi-step flow fit takes for `values` data values (N m):
/// twice the data, at least [`MIN_FLOW_WEIGHTS`]. Each Levenberg–Marquardt iteration factors a
/// (N m + 2W) × W matrix, O(W³) once W outgrows the data: 8192 weights for 180 values (nearly
/// singular kernels on 60 far-off rows) took minutes per iteration and the fit seemed to hang.
/// Beyond, the kernel form (N m momenta) fits the scheme, and the report says why.
pub fn flow_weight_limit(values: usize) -> usize {
    (2 * values).max(MIN_FLOW_WEIGHTS)
}

/// The flow fit's weight limit for small data sets: one iteration's QR stays near 5e9 flops.
pub const MIN_FLOW_WEIGHTS: usize = 1024;

/// The fitted linear model in the expansion.
#[derive(Debug, Clone)]
pub struct ExpansionFit {
    pub tolerance: f64,
    pub task_radius: f64,
    pub joint: Basis,
    pub task: Basis,
    /// One stage's weights: r_V × n joint, then r_W × m task (the protocol's layout).
    pub weights: Vec<f64>,
    /// k1 at the training points, N × m, internal units.
    pub positions: Vec<f64>,
    /// max_i Σ_j |A_ij w_j| / max_i |Σ_j A_ij w_j|: how much the evaluated terms cancel.
    pub cancellation: f64,
    /// Largest |w| in prior standard deviations.
    pub largest_whitened_weight: f64,
}

impl ExpansionFit {
    pub fn len(&self) -> usize {
        self.weights.len()
    }
    pub fn is_empty(&self) -> bool {
        self.weights.is_empty()
    }
    /// The protocol's exponents of the task basis.
    pub fn task_exponents(&self) -> Vec<u8> {
        solve::task_exponents(&self.task)
    }
}

/// Why a model keeps the kernel form.
#[derive(Debug, Clone, PartialEq)]
pub enum Declined {
    /// The kernels need more terms than the protocol or [`MAX_WEIGHTS`] allow.
    TooLong(String),
    /// The whitened least-squares problem could not be solved.
    Singular,
    /// The least-squares problem would not fit in the memory this process may use.
    Memory(String),
    /// The kernel form was asked for (`--representation kernel`).
    KernelRequested,
    /// A law without the Gaussian-process prior the expansion uses (not Hamiltonian).
    NotHamiltonian,
    /// (`auto`) The expansion has more weights a stage than the kernel form has momenta, and the
    /// momenta do not cancel.
    LongerThanMomenta { weights: usize, momenta: usize, cancellation: f64 },
}

impl std::fmt::Display for Declined {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Declined::TooLong(why) => write!(f, "{why}"),
            Declined::Singular => write!(f, "the weights' least-squares problem is singular"),
            Declined::Memory(why) => write!(f, "{why}"),
            Declined::KernelRequested => write!(f, "kernel form requested"),
            Declined::NotHamiltonian => write!(f, "only the Hamiltonian laws have the Gaussian-process prior the expansion uses"),
            Declined::LongerThanMomenta { weights, momenta, cancellation } => {
                write!(f, "the expansion has {weights} weights a stage, more than the {momenta} momenta, which do not cancel ({cancellation:.1e})")
            }
        }
    }
}

/// The truncation tolerance for noise σ (internal units) and a prior of `scale²` per coordinate:
/// the dropped prior variance stays 100 × below σ² (the model cannot resolve less), no tighter
/// than 1e-14 (f64 evaluation resolves the kernel to ~1e-16 of its total) and no looser than 1e-8.
pub fn tolerance_for(sigma: f64, scale2: f64) -> f64 {
    (0.01 * sigma * sigma / scale2).clamp(1e-14, 1e-5)
}

/// The radius a task expansion must cover: 1.25 × the farthest nominal position (room for queries
/// beyond the measured ones and for the flow's displacement).
pub fn task_radius_of(nominal: &[f64], m: usize) -> f64 {
    1.25 * nominal.chunks_exact(m).map(|k| k.iter().map(|v| v * v).sum::<f64>().sqrt()).fold(0.0f64, f64::max).max(1e-3)
}

/// The functions of the linear model's expansion on `cp`'s points: which joint and task functions
/// the kernels need at the tolerance their noise allows (no solve yet: its length decides whether
/// the expansion is worth solving for).
#[derive(Debug, Clone)]
pub struct LinearBasis {
    pub tolerance: f64,
    pub task_radius: f64,
    pub joint: Basis,
    pub task: Basis,
}

impl LinearBasis {
    /// Weights of one stage: r_V × n joint, r_W × m task.
    pub fn weights(&self, n: usize, m: usize) -> usize {
        self.joint.len() * n + self.task.len() * m
    }
}

/// The expansion's functions for `joint_kernel` (blob units, γ > 0) and `task_kernel` on `cp`'s
/// points with noise `sigma`, or why there is none within the limits.
pub fn linear_basis(cp: &ControlPoints, joint_kernel: &JointKernel, task_kernel: &TaskKernel, sigma: f64) -> Result<LinearBasis, Declined> {
    let (m, n) = (cp.dims.m, cp.dims.n);
    let count = cp.len();
    let nominal = cp.nominal_positions();
    let jacobians = cp.nominal_jacobians();
    let mean_j2 = jacobians.iter().map(|v| v * v).sum::<f64>() / (count * m).max(1) as f64;
    let tolerance = tolerance_for(sigma, 1.0 + joint_kernel.gamma * mean_j2);
    let ranges: Vec<f64> = (0..n).map(|d| 1.25 * cp.points.chunks_exact(n).map(|x| x[d].abs()).fold(0.0f64, f64::max).max(1e-3)).collect();
    let joint_axes = joint_series(joint_kernel, &ranges)
        .ok_or_else(|| Declined::TooLong("the joint kernel has an axis form without a series of its own".into()))?;
    let joint = truncate(&joint_axes, tolerance).ok_or_else(|| {
        Declined::TooLong(format!("the joint kernel needs orders above 63 or over 200000 modes at tolerance {tolerance:.0e}"))
    })?;
    let task_radius = task_radius_of(&nominal, m);
    let task_axes = vec![AxisSeries::gaussian(task_radius / task_kernel.width); m];
    let task = truncate(&task_axes, tolerance)
        .ok_or_else(|| Declined::TooLong(format!("the task kernel needs orders above 63 at tolerance {tolerance:.0e}")))?;
    let weights_len = joint.len() * n + task.len() * m;
    if weights_len > MAX_WEIGHTS {
        return Err(Declined::TooLong(format!("{weights_len} weights at tolerance {tolerance:.0e} (limit {MAX_WEIGHTS})")));
    }
    Ok(LinearBasis { tolerance, task_radius, joint, task })
}

/// The linear (Euler × 1) model on `cp`'s points in the expansion of `joint_kernel` (blob units, γ > 0)
/// and `task_kernel`, fitted to `target` (N × m, internal units) with noise `sigma`.
pub fn fit_linear(
    cp: &ControlPoints,
    joint_kernel: &JointKernel,
    task_kernel: &TaskKernel,
    sigma: f64,
    target: &[f64],
) -> Result<ExpansionFit, Declined> {
    let basis = linear_basis(cp, joint_kernel, task_kernel, sigma)?;
    fit_linear_in(cp, basis, joint_kernel, task_kernel, sigma, target)
}

/// [`fit_linear`] in the functions `basis` ([`linear_basis`] of the same kernels and σ).
pub fn fit_linear_in(
    cp: &ControlPoints,
    basis: LinearBasis,
    joint_kernel: &JointKernel,
    task_kernel: &TaskKernel,
    sigma: f64,
    target: &[f64],
) -> Result<ExpansionFit, Declined> {
    let (m, n) = (cp.dims.m, cp.dims.n);
    let count = cp.len();
    let nominal = cp.nominal_positions();
    let jacobians = cp.nominal_jacobians();
    let residual: Vec<f64> = target.iter().zip(&nominal).map(|(y, k)| y - k).collect();
    let LinearBasis { tolerance, task_radius, joint, task } = basis;
    let weights_len = joint.len() * n + task.len() * m;
    crate::memory::room_for(crate::memory::expansion_bytes(count * m, weights_len), count * m + weights_len)
        .map_err(|why| Declined::Memory(format!("the expansion's {weights_len} weights {why}")))?;
    let problem = LinearProblem { dims: cp.dims, points: &cp.points, nominal: &nominal, jacobians: &jacobians, residual: &residual };
    let a = design(&problem, joint_kernel, task_kernel, &joint, &task);
    let variances = prior_variances(joint_kernel.gamma, n, m, &joint, &task);
    let weights = posterior_weights(&a, &variances, sigma, &residual).ok_or(Declined::Singular)?;
    let deformation = apply(&a, &weights);
    let positions: Vec<f64> = nominal.iter().zip(&deformation).map(|(k, d)| k + d).collect();
    let cancellation = crate::numeric::cancellation::cancellation_of(&a, &weights);
    let largest_whitened_weight = weights.iter().zip(&variances).map(|(w, v)| w.abs() / v.sqrt()).fold(0.0, f64::max);
    Ok(ExpansionFit { tolerance, task_radius, joint, task, weights, positions, cancellation, largest_whitened_weight })
}

#[cfg(test)]
mod tests;

/// A multi-step scheme's fields in the expansion, fitted in weight space ([`flow_fit`]): the linear
/// model's bases and weights (`linear`, from [`fit_linear`]) as the start, then Levenberg–Marquardt on
/// the whitened per-stage weights. Returns the fit (all stages' weights), its iterations and whether it
/// converged.
#[allow(clippy::too_many_arguments)]
pub fn fit_flow(
    cp: &ControlPoints,
    joint_kernel: &JointKernel,
    task_kernel: &TaskKernel,
    sigma: f64,
    target: &[f64],
    linear: ExpansionFit,
    integrator: cbd_protocol::Integrator,
    max_iterations: usize,
    relative_tolerance: f64,
    prediction_tolerance: f64,
) -> Result<(ExpansionFit, usize, bool), Declined> {
    let (m, n) = (cp.dims.m, cp.dims.n);
    let params = linear.len() * integrator.stage_count();
    if params > MAX_WEIGHTS {
        return Err(Declined::TooLong(format!("{params} weights over {} stages (limit {MAX_WEIGHTS})", integrator.stage_count())));
    }
    let limit = flow_weight_limit(cp.len() * m);
    if params > limit {
        return Err(Declined::TooLong(format!(
            "{params} weights over {} stages for {} data values: each iteration's least squares would cost {:.1e} flops (limit {limit} weights: twice the data, at least {MIN_FLOW_WEIGHTS})",
            integrator.stage_count(),
            cp.len() * m,
            2.0 * (cp.len() * m + 2 * params) as f64 * (params as f64).powi(2)
        )));
    }
    crate::memory::room_for(crate::memory::flow_expansion_bytes(cp.len() * m, params), cp.len() * m + 2 * params)
        .map_err(|why| Declined::Memory(format!("the {params} weights over {} stages {why}", integrator.stage_count())))?;
    let initial = cp.nominal_kinematics();
    let problem = flow_fit::StageProblem::new(
        cp.dims,
        &cp.points,
        initial,
        target,
        joint_kernel,
        task_kernel,
        &linear.joint,
        &linear.task,
        sigma,
        integrator,
    );
    // Two starts: the linear model on the first stage alone (its data fit exactly, a larger path
    // energy) and the same fields on every stage (first-order equal, a smaller energy); the one
    // with the lower energy goes on.
    let start = [problem.first_stage_start(&linear.weights), problem.uniform_start(&linear.weights)]
        .into_iter()
        .filter_map(|z| problem.energy(&z).map(|e| (e, z)))
        .min_by(|a, b| a.0.total_cmp(&b.0))
        .map(|(_, z)| z)
        .ok_or(Declined::Singular)?;
    let (z, positions, iterations, converged) =
        flow_fit::minimise(&problem, start, max_iterations, relative_tolerance, prediction_tolerance).ok_or(Declined::Singular)?;
    let weights = problem.weights_of(&z);
    // The cancellation of the terms the runtime sums, on the linear design with the path's mean field.
    let quadrature = flow_fit::quadrature(integrator);
    let mean: Vec<f64> =
        (0..linear.len()).map(|k| quadrature.iter().enumerate().map(|(s, q)| q * weights[s * linear.len() + k]).sum()).collect();
    let nominal = cp.nominal_positions();
    let jacobians = cp.nominal_jacobians();
    let lp = LinearProblem { dims: cp.dims, points: &cp.points, nominal: &nominal, jacobians: &jacobians, residual: target };
    let a = design(&lp, joint_kernel, task_kernel, &linear.joint, &linear.task);
    let cancellation = crate::numeric::cancellation::cancellation_of(&a, &mean);
    let variances = prior_variances(joint_kernel.gamma, n, m, &linear.joint, &linear.task);
    let largest_whitened_weight =
        weights.iter().enumerate().map(|(k, w)| w.abs() / variances[k % variances.len()].sqrt()).fold(0.0, f64::max);
    let fit = ExpansionFit { weights, positions, cancellation, largest_whitened_weight, ..linear };
    Ok((fit, iterations, converged))
}

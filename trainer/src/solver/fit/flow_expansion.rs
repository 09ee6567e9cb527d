//! Schemes written as expansions (docs/DESIGN.md §11, issue 25): multi-step schemes as per-stage
//! expansions fitted in weight space ([`crate::expansion::fit_flow`]), not through momenta that
//! cancel, and the linear scheme beyond the closed form's dense size. The blob's kernel form holds
//! the linearised model's momenta α = (K_lin + σ² I)⁻¹ r — the start of every scheme — as its
//! reference: by a dense Cholesky up to [`DENSE_MAX_UNKNOWNS`], else from the expansion's own
//! linear fit, α = (r − A w)/σ² (the truncated kernel's α; no (N m)² matrix is formed).

use super::encode::encode_checked;
use super::problem::cancellation_of;
use super::{CbdFit, CbdOptions, ExpansionReport, FitError, FitReport, IterationLog, DENSE_MAX_UNKNOWNS};
use crate::data::Measurements;
use crate::expansion::{fit_flow, fit_linear, fit_linear_in, linear_basis, Declined, ExpansionFit, Representation, CANCELLATION_LIMIT};
use crate::flow::ControlPoints;
use crate::numeric::FIXED_SPLIT;
use crate::solver::regulariser::regulariser_matrix;
use crate::solver::step::solve_regularised;
use cbd_protocol::NominalModel;
use std::time::Instant;

/// What the fits here are given: the problem the kernel form's solver would solve.
#[derive(Clone, Copy)]
pub(super) struct ExpansionInputs<'a> {
    pub nominal: &'a NominalModel,
    pub data: &'a Measurements,
    pub opts: &'a CbdOptions,
    pub cp: &'a ControlPoints,
    pub target: &'a [f64],
    pub start: Instant,
}

/// The fit in weight space — of a multi-step scheme, or of the linear scheme (`linear_scheme`)
/// beyond the closed form's dense size —, or `Ok(Err(why))` when the kernel form's own solver
/// should run instead (the kernel form requested, or as each fit below says).
pub(super) fn fit(inputs: ExpansionInputs<'_>, linear_scheme: bool) -> Result<Result<CbdFit, Declined>, FitError> {
    if inputs.opts.solver.representation == Representation::Kernel {
        return Ok(Err(Declined::KernelRequested));
    }
    if linear_scheme {
        fit_linear_scheme(inputs)
    } else {
        fit_multi_step(inputs)
    }
}

/// A multi-step scheme in weight space; declined for a non-Hamiltonian law, too many momenta for
/// the dense linear start, kernels without a usable expansion, or (`Auto`) an expansion longer
/// than the momenta while the momenta do not cancel.
fn fit_multi_step(inputs: ExpansionInputs<'_>) -> Result<Result<CbdFit, Declined>, FitError> {
    let ExpansionInputs { nominal, data, opts, cp, target, start } = inputs;
    let m = cp.dims.m;
    if opts.solver.law.joint_field_sign() > 0.0 {
        return Ok(Err(Declined::NotHamiltonian));
    }
    // The linear model's expansion first: the flow starts from it, and `auto` decides on its length
    // — before solving for it when the dense momenta can say (the six-joint arm at N = 60: 2946
    // weights for 180 momenta, a second of QR each fit for a model `auto` then declines).
    let basis = match linear_basis(cp, &opts.joint_kernel, &opts.task_kernel, opts.sigma) {
        Ok(b) => b,
        Err(why) => return Ok(Err(why)),
    };
    let (weights, momenta_len) = (basis.weights(cp.dims.n, m), cp.len() * m);
    let longer = opts.solver.representation == Representation::Auto && weights > momenta_len;
    let dense = if longer && momenta_len <= DENSE_MAX_UNKNOWNS { Some(dense_momenta(cp, opts, target)?) } else { None };
    // A cancellation not measured (NaN, large N) is not known to be large.
    if let Some((_, cancellation)) = dense.as_ref().filter(|(_, c)| !(*c > CANCELLATION_LIMIT)) {
        return Ok(Err(Declined::LongerThanMomenta { weights, momenta: momenta_len, cancellation: *cancellation }));
    }
    let linear = match fit_linear_in(cp, basis, &opts.joint_kernel, &opts.task_kernel, opts.sigma, target) {
        Ok(l) => l,
        Err(Declined::Memory(why)) => return Err(FitError::Memory(why)),
        Err(why) => return Ok(Err(why)),
    };
    let (momenta, kernel_cancellation) = match dense {
        Some(d) => d,
        None => linear_momenta(cp, opts, target, &linear)?,
    };
    if longer && !(kernel_cancellation > CANCELLATION_LIMIT) {
        return Ok(Err(Declined::LongerThanMomenta { weights, momenta: momenta_len, cancellation: kernel_cancellation }));
    }
    let (e, iterations, converged) = match fit_flow(
        cp,
        &opts.joint_kernel,
        &opts.task_kernel,
        opts.sigma,
        target,
        linear,
        opts.integrator,
        opts.solver.max_iterations,
        opts.solver.relative_tolerance,
        opts.solver.prediction_tolerance,
    ) {
        Ok(r) => r,
        Err(Declined::Memory(why)) => return Err(FitError::Memory(why)),
        Err(why) => return Ok(Err(why)),
    };
    let norm = &opts.normalisation;
    let user = |k: &[f64]| -> Vec<f64> { k.chunks_exact(m).flat_map(|k| (0..m).map(move |c| norm.position_to_user(c, k[c]))).collect() };
    let train_predictions = user(&e.positions);
    let rms = |k: &[f64]| {
        let sum: f64 = k.iter().zip(target).map(|(a, b)| (a - b) * (a - b)).sum();
        norm.length_to_user((sum / cp.len().max(1) as f64).sqrt())
    };
    let (blob, max_runtime_trainer_diff) = encode_checked(nominal, data, opts, &momenta, Some(&e), &train_predictions)?;
    let seconds = start.elapsed().as_secs_f64();
    let last = IterationLog {
        iteration: iterations,
        energy: f64::NAN,
        regulariser: f64::NAN,
        train_rms: rms(&e.positions),
        damping: 0.0,
        seconds,
    };
    let stop_reason =
        if converged { "converged (per-stage weights, Levenberg–Marquardt)" } else { "iteration limit (per-stage weights)" };
    // The kernel form holds the linearised model, not this flow: no like-for-like difference.
    let report = expansion_report(&e, stop_reason, last, iterations, kernel_cancellation, max_runtime_trainer_diff);
    let report = FitReport { converged, ..report };
    if opts.solver.verbose {
        errln!(
            "expansion: {} weights over {} stages ({} joint, {} task functions, tolerance {:.0e}), {iterations} iterations, training RMS {:.3e}",
            e.len(),
            opts.integrator.stage_count(),
            e.joint.len(),
            e.task.len(),
            e.tolerance,
            last.train_rms
        );
    }
    Ok(Ok(CbdFit { blob, momenta, train_predictions, report }))
}

/// The linearised model's momenta α = (K_lin + σ² I)⁻¹ r (the blob's kernel form) and their
/// cancellation: a dense Cholesky up to [`DENSE_MAX_UNKNOWNS`] unknowns, else α = (r − A w)/σ² from the
/// expansion's linear fit `linear`, cancellation NaN (it would need the (N m)² matrix).
fn linear_momenta(cp: &ControlPoints, opts: &CbdOptions, target: &[f64], linear: &ExpansionFit) -> Result<(Vec<f64>, f64), FitError> {
    if cp.len() * cp.dims.m <= DENSE_MAX_UNKNOWNS {
        return dense_momenta(cp, opts, target);
    }
    let sigma2 = opts.sigma * opts.sigma;
    Ok((target.iter().zip(&linear.positions).map(|(y, k)| (y - k) / sigma2).collect(), f64::NAN))
}

/// α = (K_lin + σ² I)⁻¹ r by a dense Cholesky, and its cancellation.
fn dense_momenta(cp: &ControlPoints, opts: &CbdOptions, target: &[f64]) -> Result<(Vec<f64>, f64), FitError> {
    let k_reg = regulariser_matrix(cp);
    let nominal_positions = cp.nominal_positions();
    let residual: Vec<f64> = target.iter().zip(&nominal_positions).map(|(y, k)| y - k).collect();
    let momenta = solve_regularised(&k_reg, opts.sigma, &residual, FIXED_SPLIT).ok_or(FitError::Singular { iteration: 0, damping: 0.0 })?;
    let cancellation = cancellation_of(&k_reg, &momenta);
    Ok((momenta, cancellation))
}

/// The linear scheme (Euler × 1) beyond [`super::CLOSED_FORM_MAX_UNKNOWNS`]: the expansion's weights by
/// its QR (O(N m r²)) and the kernel form's momenta from them, instead of the (N m)² closed form;
/// `Ok(Err(why))` when the expansion cannot serve (the kernel form's solver then runs).
fn fit_linear_scheme(inputs: ExpansionInputs<'_>) -> Result<Result<CbdFit, Declined>, FitError> {
    let ExpansionInputs { nominal, data, opts, cp, target, start } = inputs;
    let linear = match fit_linear(cp, &opts.joint_kernel, &opts.task_kernel, opts.sigma, target) {
        Ok(l) => l,
        Err(Declined::Memory(why)) => return Err(FitError::Memory(why)),
        Err(why) => return Ok(Err(why)),
    };
    let (momenta, kernel_cancellation) = linear_momenta(cp, opts, target, &linear)?;
    let norm = &opts.normalisation;
    let m = cp.dims.m;
    let train_predictions: Vec<f64> =
        linear.positions.chunks_exact(m).flat_map(|k| (0..m).map(move |c| norm.position_to_user(c, k[c]))).collect();
    let (blob, max_runtime_trainer_diff) = encode_checked(nominal, data, opts, &momenta, Some(&linear), &train_predictions)?;
    let sum: f64 = linear.positions.iter().zip(target).map(|(a, b)| (a - b) * (a - b)).sum();
    let train_rms = norm.length_to_user((sum / cp.len().max(1) as f64).sqrt());
    let seconds = start.elapsed().as_secs_f64();
    let log = IterationLog { iteration: 1, energy: f64::NAN, regulariser: f64::NAN, train_rms, damping: 0.0, seconds };
    // The momenta come from the expansion: no independent kernel-form difference.
    let stop_reason = "closed form (the linearised model: Euler × 1, in the expansion)";
    let report = FitReport { tangents: 0, ..expansion_report(&linear, stop_reason, log, 1, kernel_cancellation, max_runtime_trainer_diff) };
    if opts.solver.verbose {
        errln!(
            "expansion: {} weights ({} joint, {} task functions, tolerance {:.0e}), closed form in weight space, cancellation {:.1e}",
            linear.len(),
            linear.joint.len(),
            linear.task.len(),
            linear.tolerance,
            linear.cancellation
        );
    }
    Ok(Ok(CbdFit { blob, momenta, train_predictions, report }))
}

/// The fit report of a blob whose fields are the expansion `e` (converged; `tangents` = `iterations`,
/// the flow fit's count of tangent solves); `last` is the final iteration's log.
fn expansion_report(
    e: &ExpansionFit,
    stop_reason: &str,
    last: IterationLog,
    iterations: usize,
    kernel_cancellation: f64,
    max_runtime_trainer_diff: f64,
) -> FitReport {
    let seconds = last.seconds;
    FitReport {
        iterations,
        converged: true,
        stop_reason: stop_reason.into(),
        log: vec![last],
        seconds,
        seconds_flow: 0.0,
        seconds_tangent: 0.0,
        seconds_solve: seconds,
        tangents: iterations,
        method: "expansion".into(),
        unknowns: e.len(),
        seconds_basis: 0.0,
        max_runtime_trainer_diff,
        cancellation: e.cancellation,
        kernel_cancellation,
        representation: "expansion".into(),
        expansion: Some(ExpansionReport::of(e, f64::NAN)),
        expansion_declined: None,
    }
}

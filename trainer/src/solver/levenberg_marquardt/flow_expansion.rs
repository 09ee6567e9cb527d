//! Multi-step schemes written as per-stage expansions (docs/DESIGN.md §11, issue 25): the blob's
//! fields are fitted in weight space ([`crate::expansion::fit_flow`]), not through momenta that
//! cancel; the blob's kernel form holds the linearised model's momenta (K_lin + σ² I)⁻¹ r — the
//! start of every scheme — as its reference.

use super::encode::encode_checked;
use super::problem::cancellation_of;
use super::{CbdFit, CbdOptions, ExpansionReport, FitError, FitReport, IterationLog, DENSE_MAX_UNKNOWNS, FIXED_SPLIT};
use crate::data::Measurements;
use crate::expansion::{fit_flow, fit_linear, Declined, Representation, CANCELLATION_LIMIT};
use crate::flow::ControlPoints;
use crate::solver::regulariser::regulariser_matrix;
use crate::solver::step::solve_regularised;
use cbd_protocol::NominalModel;
use std::time::Instant;

/// The fit of a multi-step scheme in weight space, or `None` (with the reason) when the kernel
/// form's own solver should run instead: the kernel form requested, a non-Hamiltonian law, too
/// many momenta for the dense linear start, kernels without a usable expansion, or (`Auto`) an
/// expansion longer than the momenta while the momenta do not cancel.
pub(super) fn fit(
    nominal: &NominalModel,
    data: &Measurements,
    opts: &CbdOptions,
    cp: &ControlPoints,
    target: &[f64],
    start: Instant,
) -> Result<Result<CbdFit, String>, FitError> {
    let m = cp.dims.m;
    if opts.representation == Representation::Kernel {
        return Ok(Err("kernel form requested".into()));
    }
    if opts.law.joint_field_sign() > 0.0 {
        return Ok(Err("only the Hamiltonian laws have the Gaussian-process prior the expansion uses".into()));
    }
    if cp.len() * m > DENSE_MAX_UNKNOWNS {
        return Ok(Err(format!("more than {DENSE_MAX_UNKNOWNS} momenta for the linearised start")));
    }
    let k_reg = regulariser_matrix(cp);
    let nominal_positions = cp.nominal_positions();
    let residual: Vec<f64> = target.iter().zip(&nominal_positions).map(|(y, k)| y - k).collect();
    let momenta = solve_regularised(&k_reg, opts.sigma, &residual, FIXED_SPLIT).ok_or(FitError::Singular { iteration: 0, damping: 0.0 })?;
    let kernel_cancellation = cancellation_of(&k_reg, &momenta);
    // The linear model's expansion first: the flow starts from it, and `auto` decides on its length.
    let linear = match fit_linear(cp, &opts.joint_kernel, &opts.task_kernel, opts.sigma, target) {
        Ok(l) => l,
        Err(Declined::Memory(why)) => return Err(FitError::Memory(why)),
        Err(why) => return Ok(Err(why.to_string())),
    };
    if opts.representation == Representation::Auto && linear.len() > cp.len() * m && kernel_cancellation <= CANCELLATION_LIMIT {
        return Ok(Err(format!(
            "the expansion has {} weights a stage, more than the {} momenta, which do not cancel ({kernel_cancellation:.1e})",
            linear.len(),
            cp.len() * m
        )));
    }
    let (e, iterations, converged) = match fit_flow(
        cp,
        &opts.joint_kernel,
        &opts.task_kernel,
        opts.sigma,
        target,
        linear,
        opts.integrator,
        opts.max_iterations,
        opts.relative_tolerance,
        opts.prediction_tolerance,
    ) {
        Ok(r) => r,
        Err(Declined::Memory(why)) => return Err(FitError::Memory(why)),
        Err(why) => return Ok(Err(why.to_string())),
    };
    let norm = &opts.normalisation;
    let user = |k: &[f64]| -> Vec<f64> {
        k.chunks_exact(m).flat_map(|k| (0..m).map(move |c| norm.task_offset[c] + norm.task_scale * k[c])).collect()
    };
    let train_predictions = user(&e.positions);
    let rms = |k: &[f64]| {
        let sum: f64 = k.iter().zip(target).map(|(a, b)| (a - b) * (a - b)).sum();
        norm.task_scale * (sum / cp.len().max(1) as f64).sqrt()
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
    let report = FitReport {
        iterations,
        converged,
        stop_reason: if converged { "converged (per-stage weights, Levenberg–Marquardt)" } else { "iteration limit (per-stage weights)" }
            .into(),
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
        // The kernel form holds the linearised model, not this flow: no like-for-like difference.
        expansion: Some(ExpansionReport::of(&e, f64::NAN)),
        expansion_declined: None,
    };
    if opts.verbose {
        eprintln!(
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

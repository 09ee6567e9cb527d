//! The fit of a model with the configuration-dependent task term (docs/DESIGN.md §16): the blob
//! format carries it for Euler × 1 with the Hamiltonian law in the kernel form only, where the flow
//! is linear, k1 = k0 + K_lin P0 with K_lin = Dk0 K_V Dk0ᵀ + K_W I + γ_C K̃_Q K̃_X I, and energy (16)'s
//! minimiser is P0 = (K_lin + σ² I)⁻¹ (y − k0) in closed form. No scheme, no expansion, no iteration.

use super::{encode, kernel_form_bytes, CbdFit, CbdOptions, FitError, FitReport, IterationLog};
use crate::data::Measurements;
use crate::flow::ControlPoints;
use crate::solver::regulariser::k_lin_with_configuration;
use cbd_protocol::{ConfigurationKernel, IntegratorMethod, NominalModel};
use faer::Mat;
use std::time::Instant;

/// Why the configuration term cannot be fitted with these options, if it cannot.
pub(super) fn unsupported(opts: &CbdOptions) -> Option<String> {
    let linear = opts.integrator.method == IntegratorMethod::Euler && opts.integrator.steps == 1;
    if !linear {
        return Some(format!(
            "configuration_kernel: the blob format evaluates the configuration field with Euler × 1 only (the scheme is {:?} × {})",
            opts.integrator.method, opts.integrator.steps
        ));
    }
    if opts.solver.law.joint_field_sign() > 0.0 {
        return Some("configuration_kernel: only the Hamiltonian law has the Gaussian-process prior the term's closed form uses".into());
    }
    None
}

/// K_lin with the term, P0 and k1 (internal units).
type ClosedForm = (Mat<f64>, Vec<f64>, Vec<f64>);

/// P0 = (K_lin + σ² I)⁻¹ (y − k0) and k1 = k0 + K_lin P0 at the control points (internal units), with
/// the term's K_lin.
pub(super) fn closed_form(
    cp: &ControlPoints,
    configuration: &ConfigurationKernel,
    sigma: f64,
    target: &[f64],
) -> Result<ClosedForm, FitError> {
    let (m, count) = (cp.dims.m, cp.len());
    let k = k_lin_with_configuration(cp, configuration);
    let len = cp.dims.state_len();
    let k0: Vec<f64> = (0..count).flat_map(|i| cp.initial[i * len..i * len + m].iter().copied()).collect();
    let r: Vec<f64> = target.iter().zip(&k0).map(|(y, k)| y - k).collect();
    // P0 = (K_lin + σ² I)⁻¹ (y − k0).
    let momenta = crate::solver::step::solve_regularised(&k, sigma, &r, crate::numeric::FIXED_SPLIT)
        .ok_or(FitError::Singular { iteration: 0, damping: 0.0 })?;
    // k1 = k0 + K_lin P0.
    let mut k1 = k0;
    for (j, pj) in momenta.iter().enumerate() {
        for (s, kij) in k1.iter_mut().zip(k.col(j).iter()) {
            *s += kij * pj;
        }
    }
    Ok((k, momenta, k1))
}

/// The fitted model with the term at `query` (configurations, N_q × n), user units: k0(ξ) +
/// Σ_j [J(ξ) K_V(ξ, q_j) J_jᵀ + K_W(k0(ξ), k0_j) I + c_j(ξ) I] P_j (the Euler × 1 flow, §16), from the
/// trainer's own kernels: the reference the runtime's evaluation of the blob is checked against.
pub fn predict_with_configuration(
    nominal: &NominalModel,
    opts: &CbdOptions,
    points: &[f64],
    momenta: &[f64],
    query: &[f64],
) -> Option<Vec<f64>> {
    let configuration = opts.configuration_kernel.as_ref()?;
    let n = nominal.n_joints();
    let (count, queries) = (points.len() / n, query.len() / n);
    let all: Vec<f64> = points.iter().chain(query).copied().collect();
    let cp = ControlPoints::new(
        nominal,
        &opts.normalisation,
        all,
        opts.joint_kernel.clone(),
        opts.task_kernel,
        opts.solver.law,
        opts.integrator,
    );
    let (m, len) = (cp.dims.m, cp.dims.state_len());
    let k = k_lin_with_configuration(&cp, configuration);
    let norm = &opts.normalisation;
    Some(
        (0..queries)
            .flat_map(|q| {
                let row = count + q;
                let k = &k;
                let k0 = &cp.initial[row * len..row * len + m];
                (0..m).map(move |a| {
                    let moved: f64 = (0..count * m).map(|c| k[(row * m + a, c)] * momenta[c]).sum();
                    norm.position_to_user(a, k0[a] + moved)
                })
            })
            .collect(),
    )
}

/// The momenta of the model `opts` describes (with its configuration kernel) fitted to `data` on
/// `nominal`, without encoding a blob: what [`predict_with_configuration`] takes.
pub fn solve_with_configuration(nominal: &NominalModel, data: &Measurements, opts: &CbdOptions) -> Result<Vec<f64>, FitError> {
    let configuration =
        opts.configuration_kernel.as_ref().ok_or_else(|| FitError::Configuration("configuration_kernel: none in these options".into()))?;
    if let Some(why) = unsupported(opts) {
        return Err(FitError::Configuration(why));
    }
    let (cp, target) = super::control_points_and_target(nominal, data, opts);
    Ok(closed_form(&cp, configuration, opts.sigma, &target)?.1)
}

/// Fits the momenta of the model with `configuration` in closed form and encodes it (the runtime
/// checks the blob as for every other fit).
pub(super) fn fit(
    nominal: &NominalModel,
    data: &Measurements,
    opts: &CbdOptions,
    cp: &ControlPoints,
    configuration: &ConfigurationKernel,
    target: &[f64],
    start: Instant,
) -> Result<CbdFit, FitError> {
    if let Some(why) = unsupported(opts) {
        return Err(FitError::Configuration(why));
    }
    let (m, count) = (cp.dims.m, cp.len());
    let unknowns = count * m;
    if let Some(budget) = opts.solver.memory_budget.filter(|b| kernel_form_bytes(unknowns) > *b) {
        let expansion_declined = "the configuration field has no expansion (kernel form only)".to_string();
        return Err(FitError::TooLarge { unknowns, task_dim: m, need: kernel_form_bytes(unknowns), budget, expansion_declined });
    }
    crate::memory::note_need(kernel_form_bytes(unknowns), unknowns);
    let t0 = Instant::now();
    let (k, momenta, internal) = closed_form(cp, configuration, opts.sigma, target)?;
    let moved: Vec<f64> = {
        let len = cp.dims.state_len();
        let k0 = (0..count).flat_map(|i| cp.initial[i * len..i * len + m].iter().copied());
        internal.iter().zip(k0).map(|(a, b)| a - b).collect()
    };
    let norm = &opts.normalisation;
    let train_predictions: Vec<f64> = internal.chunks_exact(m).flat_map(|k| (0..m).map(move |c| norm.position_to_user(c, k[c]))).collect();
    let seconds_solve = t0.elapsed().as_secs_f64();
    let regulariser = 0.5 * momenta.iter().zip(&moved).map(|(p, kp)| p * kp).sum::<f64>();
    let misfit: f64 = internal.iter().zip(target).map(|(a, y)| (a - y).powi(2)).sum();
    let energy = regulariser + 0.5 * misfit / (opts.sigma * opts.sigma);
    let train_rms = norm.length_to_user((misfit / count as f64).sqrt());
    let cancellation = crate::numeric::cancellation::cancellation_of(&k, &momenta);
    let (blob, max_runtime_trainer_diff) = encode::encode_checked(nominal, data, opts, &momenta, None, &train_predictions)?;
    let seconds = start.elapsed().as_secs_f64();
    Ok(CbdFit {
        blob,
        momenta,
        train_predictions,
        report: FitReport {
            iterations: 0,
            converged: true,
            stop_reason: "closed form: Euler × 1 with the configuration field, (K_lin + σ² I)⁻¹ r".into(),
            log: vec![IterationLog { iteration: 0, energy, regulariser, train_rms, damping: 0.0, seconds }],
            seconds,
            seconds_flow: 0.0,
            seconds_tangent: 0.0,
            seconds_solve,
            tangents: 0,
            method: "dense".into(),
            unknowns,
            seconds_basis: 0.0,
            max_runtime_trainer_diff,
            cancellation,
            kernel_cancellation: cancellation,
            representation: "kernel".into(),
            expansion: None,
            expansion_declined: Some("the configuration field is evaluated in the kernel form only (blob format 8)".into()),
        },
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::simulate::six_joint::{random_configurations, SixJointRobot};
    use cbd_protocol::{Integrator, JointKernelAxis, MomentumLaw, Normalisation};

    fn six_joint_options(norm: &Normalisation) -> CbdOptions {
        let axes = [0.3, 1.1, 0.7, 2.0, 0.05, 0.4].map(|b| JointKernelAxis::Periodic { b });
        let mut opts = CbdOptions::new(
            crate::solver::FlowHyperparameters {
                joint_kernel: cbd_protocol::JointKernel { gamma: 1e-3, axes: heapless::Vec::from_slice(&axes).unwrap() },
                task_kernel: cbd_protocol::TaskKernel { width: 0.8 },
                sigma: 0.05,
                configuration_kernel: Some(ConfigurationKernel {
                    gamma: 0.4,
                    axes: heapless::Vec::from_slice(&[2.0, 0.5, 0.5, 0.1, 0.1, 0.1].map(|b| JointKernelAxis::Periodic { b })).unwrap(),
                    task_width: Some(1.5),
                }),
            },
            Integrator { method: IntegratorMethod::Euler, steps: 1 },
            norm.clone(),
        );
        opts.solver.law = MomentumLaw::Hamiltonian;
        // The format records σ with the term (validate.rs).
        opts.noise_sigma = Some(0.05);
        opts
    }

    /// The trainer's prediction with the term at the training points is the closed form's k1, and
    /// the runtime evaluating the written blob reproduces it (within the fit's own 1e-12 check), at
    /// the training points and at fresh ones.
    #[test]
    fn the_runtime_reproduces_the_trainers_predictions_with_the_term() {
        let robot = SixJointRobot::ur5_like(3);
        let data = robot.measure(&random_configurations(40, 4), 5);
        let norm = data.normalisation();
        let opts = six_joint_options(&norm);
        let momenta = solve_with_configuration(&robot.nominal, &data, &opts).unwrap();
        let predicted = predict_with_configuration(&robot.nominal, &opts, &data.joints, &momenta, &data.joints).unwrap();
        let fit = crate::solver::fit_cbd(&robot.nominal, &data, &opts).unwrap();
        let worst = fit.train_predictions.iter().zip(&predicted).fold(0.0f64, |w, (a, b)| w.max((a - b).abs()));
        assert!(worst < 1e-9, "trainer's prediction vs the fit's: {worst:e}");
        assert!(fit.report.max_runtime_trainer_diff <= 1e-12);
        // The blob carries the term, and the runtime evaluating it at fresh poses is the trainer's prediction there.
        assert!(cbd_protocol::decode(&fit.blob).unwrap().configuration_kernel.is_some());
        let fresh = random_configurations(25, 9);
        let runtime = crate::predict::evaluate_blob(&fit.blob, &fresh).unwrap();
        let trainer = predict_with_configuration(&robot.nominal, &opts, &data.joints, &momenta, &fresh).unwrap();
        let worst = runtime.iter().zip(&trainer).fold(0.0f64, |w, (a, b)| w.max((a - b).abs()));
        assert!(worst < 1e-9, "runtime vs trainer at fresh poses: {worst:e}");
        // The closed form's k1 at the training points is the prediction there.
        let (cp, target) = super::super::control_points_and_target(&robot.nominal, &data, &opts);
        let (_, _, k1) = closed_form(&cp, opts.configuration_kernel.as_ref().unwrap(), opts.sigma, &target).unwrap();
        for (i, v) in k1.iter().enumerate() {
            let user = norm.position_to_user(i % 3, *v);
            assert!((user - predicted[i]).abs() <= 1e-9 * user.abs().max(1.0), "row {}: {user} vs {}", i / 3, predicted[i]);
        }
    }

    /// Schemes and laws the format does not evaluate the term with are refused by name.
    #[test]
    fn other_schemes_are_refused_by_name() {
        let mut opts = six_joint_options(&Normalisation::IDENTITY);
        opts.integrator.steps = 2;
        assert!(unsupported(&opts).unwrap().starts_with("configuration_kernel: "));
        opts.integrator.steps = 1;
        opts.solver.law = MomentumLaw::WithDivergence;
        assert!(unsupported(&opts).unwrap().starts_with("configuration_kernel: "));
    }
}

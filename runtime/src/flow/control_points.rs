//! The control points' flow (eq. 17, 19): their initial state from the nominal model and the
//! fixed-step integration that stores every stage's sample. The calibrator runs it once when it
//! loads a blob; the trainer runs the same code (same bits) in its solver.

use crate::error::Error;
use crate::flow::{control_point_rates, control_point_rates_with_features, write_samples, Dims, FlowParams};
use crate::integrate::{integrate_checked, scratch_len};
use crate::kernel::{features_len, JointAxes};
use crate::kinematics::{forward_kinematics, with_tool_point, Kinematics};
use crate::real::Real;
use cbd_protocol::{Integrator, Model, NominalModel, MAX_JOINTS};

/// Sets the initial control-point state: k_i = k0(x_i), J_i = Dk0(x_i), P_i = P0_i (internal units);
/// with m_p tool points, k0 and Dk0 of control point i are tool point i % m_p's (one copy of the
/// nominal model per tool point; none for a model without tool points).
pub fn initial_state(model: &Model<'_>, state: &mut [Real]) -> Result<(), Error> {
    let dims = Dims { n: model.n_joints(), m: model.task_dim() };
    if dims.state_len() == 0 {
        return Err(Error::Internal);
    }
    let m_p = model.nominal.tool_point_count();
    for j in 0..m_p {
        with_tool_point(&model.nominal, j, |nominal| {
            // Control points j, j + m_p, …: i mod m_p = j (checked_rem: no division-by-zero path).
            for (i, s) in state.chunks_exact_mut(dims.state_len().max(1)).enumerate().filter(|(i, _)| i.checked_rem(m_p) == Some(j)) {
                initial_point(model, nominal, i, s)?;
            }
            Ok::<(), Error>(())
        })
        .ok_or(Error::Internal)??;
    }
    Ok(())
}

/// Control point i's initial state, k0 and Dk0 from `nominal` (the model of its tool point).
fn initial_point(model: &Model<'_>, nominal: &NominalModel, i: usize, s: &mut [Real]) -> Result<(), Error> {
    let (m, n) = (model.task_dim(), model.n_joints());
    let mut x = [0.0; MAX_JOINTS];
    for (d, xd) in x.iter_mut().enumerate().take(n) {
        *xd = model.points.get(i * n + d).ok_or(Error::Internal)?;
    }
    let k0 = forward_kinematics(nominal, x.get(..n).ok_or(Error::Internal)?).normalised(&model.normalisation);
    let (s_k, rest) = s.split_at_mut_checked(m).ok_or(Error::Internal)?;
    let (s_jac, s_p) = rest.split_at_mut_checked(m * n).ok_or(Error::Internal)?;
    copy_kinematics(&k0, s_k, s_jac, n);
    for (a, p) in s_p.iter_mut().enumerate() {
        *p = model.momenta.get(i * m + a).ok_or(Error::Internal)? as Real;
    }
    Ok(())
}

/// Copies k0 into a state's `k` (m values) and `J` (m × n, row-major) parts.
fn copy_kinematics(k0: &Kinematics, k: &mut [Real], jac: &mut [Real], n: usize) {
    if n == 0 {
        return;
    }
    for (dst, src) in k.iter_mut().zip(k0.position.iter()) {
        *dst = *src as Real;
    }
    for (dst, src) in jac.chunks_exact_mut(n.max(1)).zip(k0.jacobian.iter()) {
        for (d, s) in dst.iter_mut().zip(src.iter()) {
            *d = *s as Real;
        }
    }
}

/// Integrates the control points (eq. 17, 19) with the model's scheme, storing the sample of
/// every stage in `trajectory` and calling `on_stage(stage, state)` with each stage's input state.
/// `state` holds the initial state on entry and the final state on return.
#[allow(clippy::too_many_arguments)]
pub fn integrate_control_points<K: JointAxes + ?Sized>(
    params: &FlowParams<'_, K>,
    integrator: Integrator,
    points: &[f64],
    state: &mut [Real],
    scratch: &mut [Real],
    trajectory: &mut [Real],
    on_stage: impl FnMut(usize, &[Real]),
) -> Result<(), Error> {
    let n_points = points.len().checked_div(params.dims.n).ok_or(Error::Internal)?;
    integrate_points(params.dims, integrator, n_points, state, scratch, trajectory, on_stage, |y, samples, out| {
        control_point_rates(params, points, y, samples, 0..n_points, out)
    })
}

/// [`integrate_control_points`] (bit-identical) from the configurations' kernel-feature table
/// ([`crate::kernel::write_features`]) instead of the configurations: no transcendental per pair but one exp.
#[allow(clippy::too_many_arguments)]
pub fn integrate_control_points_with_features<K: JointAxes + ?Sized>(
    params: &FlowParams<'_, K>,
    integrator: Integrator,
    features: &[Real],
    state: &mut [Real],
    scratch: &mut [Real],
    trajectory: &mut [Real],
    on_stage: impl FnMut(usize, &[Real]),
) -> Result<(), Error> {
    let n_points = features.len().checked_div(features_len(1, params.dims.n)).ok_or(Error::Internal)?;
    integrate_points(params.dims, integrator, n_points, state, scratch, trajectory, on_stage, |y, samples, out| {
        control_point_rates_with_features(params, features, y, samples, 0..n_points, out)
    })
}

/// The control points' integration (the one loop behind [`integrate_control_points`] and
/// [`integrate_control_points_with_features`]) with the rates of every stage computed by
/// `rates(state, samples, out)`: for the same discrete flow it must write what
/// [`control_point_rates_with_features`] writes for rows `0..n_points` — the trainer splits those
/// rows across threads (a row's rate does not depend on the split, so the bits do not either).
#[allow(clippy::too_many_arguments)]
pub fn integrate_points(
    dims: Dims,
    integrator: Integrator,
    n_points: usize,
    state: &mut [Real],
    scratch: &mut [Real],
    trajectory: &mut [Real],
    mut on_stage: impl FnMut(usize, &[Real]),
    rates: impl Fn(&[Real], &[Real], &mut [Real]),
) -> Result<(), Error> {
    let block = n_points * dims.sample_len();
    // `integrate` needs this much scratch; checked here so that a short buffer is an error, not a panic.
    // (3 × len computed with a checked multiplication, so the optimiser can drop the slice checks.)
    match state.len().checked_mul(3) {
        Some(needed) if needed == scratch_len(state.len()) && scratch.len() >= needed => {}
        _ => return Err(Error::Internal),
    }
    integrate_checked(integrator.method, integrator.steps, state, scratch, Error::Internal, |stage, y, out| {
        let samples = trajectory.get_mut(stage * block..(stage + 1) * block).ok_or(Error::Internal)?;
        write_samples(dims, y, samples);
        on_stage(stage, y);
        rates(y, samples, out);
        if out.iter().all(|v| v.is_finite()) {
            Ok(())
        } else {
            Err(Error::Diverged)
        }
    })?;
    if state.iter().all(|v| v.is_finite()) {
        Ok(())
    } else {
        Err(Error::Diverged)
    }
}

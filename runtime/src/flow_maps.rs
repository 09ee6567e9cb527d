//! The flows of a loaded model as maps (issue 15, docs/DESIGN.md §10): ψ and φ, their inverses,
//! and compensation's start k1⁻¹ = φ ∘ k0⁻¹ ∘ ψ⁻¹. ψ⁻¹ integrates the task field w backward along
//! the control points' stored trajectory (its stages in reverse order, the field negated), k0⁻¹ is
//! the nominal model's inverse kinematics ([`crate::inverse_kinematics::nominal_position`]) and φ
//! integrates the joint field v forward along the same trajectory, both with the model's
//! fixed-step scheme. The runtime's k1 integrates eq. (20) at the query with eq. (19)'s transported
//! J, which omits D²k·v, so k1 is this composition only to first order in the deformation: the
//! start misses the target by a second-order term (measured in tests/tests/cross_crate/inverse_flow.rs) plus
//! the scheme's discretisation error; Newton steps on k1 ([`crate::compensate`]) remove the rest.
//! Fixed cost, no heap, no panic. With an expansion (format 5) the stages' fields come from its
//! stage weights instead of the trajectory: w from the task basis at y, v from the joint basis at
//! the moving x (written into the queries' working space, hence `&mut Calibrator`).

use crate::error::Error;
use crate::expansion::fields::stage_weights;
use crate::expansion::{joint_row_len, write_joint_basis_with_orders};
use crate::flow::inverse::{self, Direction};
use crate::flow::{Fixed, Shape};
use crate::load::Calibrator;
use crate::real::{to_f64, Real};
use cbd_protocol::{MAX_JOINTS as NJ, MAX_TASK_DIM as MT};

/// ψ(y) (forward) or ψ⁻¹(y) (backward): the task-space flow of w along the stored trajectory,
/// `y` and `out` in user units (m values).
pub fn task_flow(cal: &Calibrator<'_>, y: &[f64], direction: Direction, out: &mut [f64]) -> Result<(), Error> {
    match (cal.dims.m, cal.dims.n) {
        (2, 2) => task_flow_shaped(cal, Fixed::<2, 2>, y, direction, out),
        (3, 6) => task_flow_shaped(cal, Fixed::<3, 6>, y, direction, out),
        _ => task_flow_shaped(cal, cal.dims, y, direction, out),
    }
}

/// φ(x) (forward) or φ⁻¹(x) (backward): the joint-space flow of v along the stored
/// trajectory, `x` and `out` joint configurations (n values).
pub fn joint_flow(cal: &mut Calibrator<'_>, x: &[f64], direction: Direction, out: &mut [f64]) -> Result<(), Error> {
    match (cal.dims.m, cal.dims.n) {
        (2, 2) => joint_flow_shaped(cal, Fixed::<2, 2>, x, direction, out),
        (3, 6) => joint_flow_shaped(cal, Fixed::<3, 6>, x, direction, out),
        _ => joint_flow_shaped(cal, cal.dims, x, direction, out),
    }
}

#[inline(always)]
fn task_flow_shaped<S: Shape>(cal: &Calibrator<'_>, shape: S, y: &[f64], direction: Direction, out: &mut [f64]) -> Result<(), Error> {
    let m = cal.dims.m;
    if y.len() != m || out.len() != m {
        return Err(Error::TargetDimension { expected: m, found: if y.len() != m { y.len() } else { out.len() } });
    }
    let norm = &cal.model.normalisation;
    let mut state = [0.0 as Real; MT];
    for (axis, (dst, v)) in state.iter_mut().zip(y).enumerate() {
        *dst = norm.position_to_internal_by_reciprocal(axis, *v) as Real;
    }
    let kernel = cal.model.task_kernel;
    let sign: Real = if direction == Direction::Forward { 1.0 } else { -1.0 };
    let block = cal.model.n_points as usize * cal.dims.sample_len();
    let trajectory: &[Real] = cal.trajectory;
    let (weights, expansion) = (cal.weights, cal.model.expansion.as_ref());
    let (stage_len, joint_len) = expansion.map_or((0, 0), |e| (e.stage_len(cal.dims.n, m), e.n_joint_features as usize * cal.dims.n));
    let task_orders = cal.orders.task;
    let state = state.get_mut(..m).ok_or(Error::Internal)?;
    inverse::flow_along_stages(cal.model.integrator, direction, state, |stage, s, rate| {
        let w = match expansion {
            None => inverse::task_velocity(shape, &kernel, s, trajectory.get(stage * block..(stage + 1) * block).ok_or(Error::Internal)?),
            Some(e) => {
                let (_, d) = stage_weights(weights, stage, stage_len, joint_len).ok_or(Error::Internal)?;
                crate::expansion::fields::task_velocity(shape, &kernel, e.task_exponents, &task_orders, d, s)
            }
        };
        for (r, w_a) in rate.iter_mut().zip(w.iter()) {
            *r = sign * w_a;
        }
        Ok(())
    })?;
    for (axis, (dst, v)) in out.iter_mut().zip(state.iter()).enumerate() {
        *dst = norm.position_to_user(axis, to_f64(*v));
    }
    if out.iter().all(|v| v.is_finite()) {
        Ok(())
    } else {
        Err(Error::NonFiniteResult)
    }
}

#[inline(always)]
fn joint_flow_shaped<S: Shape>(cal: &mut Calibrator<'_>, shape: S, x: &[f64], direction: Direction, out: &mut [f64]) -> Result<(), Error> {
    let (m, n) = (cal.dims.m, cal.dims.n);
    if x.len() != n || out.len() != n {
        return Err(Error::QueryDimension { expected: n, found: if x.len() != n { x.len() } else { out.len() } });
    }
    let mut state = [0.0 as Real; NJ];
    for (dst, v) in state.iter_mut().zip(x) {
        *dst = *v as Real;
    }
    let kernel = cal.model.joint_kernel.for_flow(cal.model.momentum_law);
    let features: &[Real] = cal.features;
    let sign: Real = if direction == Direction::Forward { 1.0 } else { -1.0 };
    let block = cal.model.n_points as usize * cal.dims.sample_len();
    let trajectory: &[Real] = cal.trajectory;
    let (weights, expansion) = (cal.weights, cal.model.expansion.as_ref());
    let (stage_len, joint_len) = expansion.map_or((0, 0), |e| (e.stage_len(n, m), e.n_joint_features as usize * n));
    // The expansion's joint basis at the moving x goes to the queries' working space.
    let rows_len = expansion.map_or(0, |e| e.n_joint_features as usize * joint_row_len(n));
    let joint_orders = cal.orders.joint;
    let rows = cal.work.get_mut(..rows_len).ok_or(Error::Internal)?;
    let state = state.get_mut(..n).ok_or(Error::Internal)?;
    inverse::flow_along_stages(cal.model.integrator, direction, state, |stage, s, rate| {
        let v = match expansion {
            None => inverse::joint_velocity(
                shape,
                &kernel,
                s,
                features,
                trajectory.get(stage * block..(stage + 1) * block).ok_or(Error::Internal)?,
            ),
            Some(e) => {
                let (c, _) = stage_weights(weights, stage, stage_len, joint_len).ok_or(Error::Internal)?;
                let mut xx = [0.0; NJ];
                for (dst, src) in xx.iter_mut().zip(s).take(n) {
                    *dst = to_f64(*src);
                }
                write_joint_basis_with_orders(
                    &cal.model.joint_kernel,
                    e.joint_codes,
                    &joint_orders,
                    n,
                    xx.get(..n).unwrap_or(&[]),
                    rows,
                    false,
                );
                crate::expansion::fields::joint_velocity(shape, c, rows)
            }
        };
        for (r, v_a) in rate.iter_mut().zip(v.iter()) {
            *r = sign * v_a;
        }
        Ok(())
    })?;
    for (dst, v) in out.iter_mut().zip(state.iter()) {
        *dst = to_f64(*v);
    }
    if out.iter().all(|v| v.is_finite()) {
        Ok(())
    } else {
        Err(Error::NonFiniteResult)
    }
}

/// k1⁻¹ = φ ∘ k0⁻¹ ∘ ψ⁻¹: the start of compensation. ψ⁻¹(target), then the nominal inverse
/// kinematics of that point from `seed` (closed form where the nominal model has one, the
/// seed's branch and orientation; otherwise `nominal_iterations` Gauss–Newton steps on k0 from
/// the seed), then φ. Writes the start to `out` (n values).
pub fn inverse_flow_start(
    cal: &mut Calibrator<'_>,
    target: &[f64],
    seed: &[f64],
    out: &mut [f64],
    nominal_iterations: usize,
) -> Result<(), Error> {
    let (m, n) = (cal.dims.m, cal.dims.n);
    if seed.len() != n || out.len() != n {
        return Err(Error::QueryDimension { expected: n, found: if seed.len() != n { seed.len() } else { out.len() } });
    }
    let mut pulled = [0.0; MT];
    let pulled = pulled.get_mut(..m).ok_or(Error::Internal)?;
    task_flow(cal, target, Direction::Backward, pulled)?;
    let mut nominal = [0.0; NJ];
    let nominal = nominal.get_mut(..n).ok_or(Error::Internal)?;
    let scale = cal.model.normalisation.task_scale;
    // k0⁻¹ of tool point 0, the point `evaluate` gives (the model itself without tool points).
    crate::kinematics::with_tool_point(&cal.model.nominal, 0, |k0| {
        crate::inverse_kinematics::nominal_position(k0, pulled, seed, nominal, nominal_iterations, scale)
    })
    .flatten()
    .ok_or(Error::NonFiniteResult)?;
    joint_flow(cal, nominal, Direction::Forward, out)
}

//! The inverse flows, compensation's start (issue 15, docs/DESIGN.md §10): k1 = ψ ∘ k0 ∘ φ⁻¹, so
//! k1⁻¹ = φ ∘ k0⁻¹ ∘ ψ⁻¹. ψ⁻¹ integrates the task field w backward along the control points'
//! stored trajectory (its stages in reverse order, the field negated), k0⁻¹ is the nominal model's
//! inverse kinematics ([`crate::inverse_kinematics::nominal_position`]) and φ integrates the joint
//! field v forward along the same trajectory, both with the model's fixed-step scheme. The runtime's
//! k1 integrates eq. (20) at the query with eq. (19)'s transported J, which omits D²k·v, so k1 is
//! this composition only to first order in the deformation: the start misses the target by a
//! second-order term (measured in tests/tests/inverse_flow.rs) plus the scheme's discretisation
//! error; Newton steps on k1 ([`crate::compensate`]) remove the rest. Fixed cost, no heap, no panic.
//! With an expansion (format 5) the stages' fields come from its stage weights instead of the
//! trajectory: w from the task basis at y, v from the joint basis at the moving x (written into
//! the queries' working space, hence `&mut self`).

use crate::expansion::fields::stage_weights;
use crate::expansion::{joint_row_len, write_joint_basis_with_orders};
use crate::flow::{Fixed, Shape};
use crate::integrate::integrate_checked;
use crate::kernel::{joint_features, joint_kernel_parts_n, FEATURES_PER_JOINT};
use crate::real::{exp, to_f64, Real};
use crate::{Calibrator, Error};
use cbd_protocol::{Integrator, JointKernel, TaskKernel, MAX_JOINTS as NJ, MAX_TASK_DIM as MT};

/// Which way a flow is integrated: from t = 0 to 1 (ψ, φ) or from t = 1 back to 0 (ψ⁻¹, φ⁻¹).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Direction {
    /// From t = 0 to 1: the flow itself.
    Forward,
    /// From t = 1 back to 0: its inverse.
    Backward,
}

/// Stage `g` of the pass in `direction` reads the stored stage `total − 1 − g` when backward: the
/// trajectory reversed, so each step of the scheme runs on the same stages as forward, mirrored.
fn stored_stage(direction: Direction, total: usize, g: usize) -> usize {
    match direction {
        Direction::Forward => g,
        Direction::Backward => total.saturating_sub(g + 1),
    }
}

/// w(y) = Σ_j K_W(y, k_j) P_j over one stage's samples (the field of [`crate::flow::task_field`],
/// without its Jacobian), internal units.
#[inline(always)]
fn task_velocity<S: Shape>(shape: S, kernel: &TaskKernel, y: &[Real], samples: &[Real]) -> [Real; MT] {
    let (m, n) = (shape.m(), shape.n());
    let width = kernel.width as Real;
    let exponent_scale = -0.5 / (width * width);
    let mut yy = [0.0; MT];
    for (dst, src) in yy.iter_mut().zip(y).take(m) {
        *dst = *src;
    }
    let mut w = [0.0; MT];
    for s in samples.chunks_exact((2 * m + n).max(1)) {
        let mut r2 = 0.0;
        for (y_c, k_c) in yy.iter().zip(s).take(m) {
            let e = y_c - k_c;
            r2 += e * e;
        }
        let kw = exp(exponent_scale * r2);
        for (w_a, p_a) in w.iter_mut().zip(s.iter().skip(m)).take(m) {
            *w_a += kw * p_a;
        }
    }
    w
}

/// v(x) = Σ_j K_V(x, x_j) u_j over one stage's samples (the field of [`crate::flow::joint_field`],
/// without its Jacobian), `kernel` the flow's kernel (its sign folded into γ), `features` the
/// configurations' [`crate::kernel::write_features`] table.
#[inline(always)]
fn joint_velocity<S: Shape>(shape: S, kernel: &JointKernel, x: &[Real], features: &[Real], samples: &[Real]) -> [Real; NJ] {
    let (m, n) = (shape.m(), shape.n());
    let mut xx = [0.0; NJ];
    for (dst, src) in xx.iter_mut().zip(x).take(n) {
        *dst = to_f64(*src);
    }
    let mut fx = [[0.0; FEATURES_PER_JOINT]; NJ];
    joint_features(kernel, xx.get(..n).unwrap_or(&[]), &mut fx);
    let mut v = [0.0; NJ];
    let (mut pairs, _) = features.as_chunks::<FEATURES_PER_JOINT>();
    for s in samples.chunks_exact((2 * m + n).max(1)) {
        let Some((fxj, rest)) = pairs.split_at_checked(n) else { break };
        pairs = rest;
        let (mut first, mut second) = ([0.0; NJ], [0.0; NJ]);
        let k = joint_kernel_parts_n(kernel, n, &fx, fxj, &mut first, &mut second);
        for (v_a, u_a) in v.iter_mut().zip(s.iter().skip(2 * m)).take(n) {
            *v_a += k * u_a;
        }
    }
    v
}

/// Integrates `state` (at most [`NJ`] values) with the model's scheme, the rate of every stage given
/// by `rate(stored stage, state, out)` — the stored stages reversed when backward.
fn flow_along_stages(
    integrator: Integrator,
    direction: Direction,
    state: &mut [Real],
    mut rate: impl FnMut(usize, &[Real], &mut [Real]) -> Result<(), Error>,
) -> Result<(), Error> {
    let total = integrator.stage_count();
    let mut scratch = [0.0 as Real; 3 * NJ];
    integrate_checked(integrator.method, integrator.steps, state, &mut scratch, Error::Internal, |g, s, out| {
        rate(stored_stage(direction, total, g), s, out)?;
        if out.iter().all(|v| v.is_finite()) {
            Ok(())
        } else {
            Err(Error::NonFiniteResult)
        }
    })
}

impl Calibrator<'_> {
    /// ψ(y) (forward) or ψ⁻¹(y) (backward): the task-space flow of w along the stored trajectory,
    /// `y` and `out` in user units (m values).
    pub fn task_flow(&self, y: &[f64], direction: Direction, out: &mut [f64]) -> Result<(), Error> {
        match (self.dims.m, self.dims.n) {
            (2, 2) => self.task_flow_shaped(Fixed::<2, 2>, y, direction, out),
            (3, 6) => self.task_flow_shaped(Fixed::<3, 6>, y, direction, out),
            _ => self.task_flow_shaped(self.dims, y, direction, out),
        }
    }

    /// φ(x) (forward) or φ⁻¹(x) (backward): the joint-space flow of v along the stored
    /// trajectory, `x` and `out` joint configurations (n values).
    pub fn joint_flow(&mut self, x: &[f64], direction: Direction, out: &mut [f64]) -> Result<(), Error> {
        match (self.dims.m, self.dims.n) {
            (2, 2) => self.joint_flow_shaped(Fixed::<2, 2>, x, direction, out),
            (3, 6) => self.joint_flow_shaped(Fixed::<3, 6>, x, direction, out),
            _ => self.joint_flow_shaped(self.dims, x, direction, out),
        }
    }

    #[inline(always)]
    fn task_flow_shaped<S: Shape>(&self, shape: S, y: &[f64], direction: Direction, out: &mut [f64]) -> Result<(), Error> {
        let m = self.dims.m;
        if y.len() != m || out.len() != m {
            return Err(Error::TargetDimension { expected: m, found: if y.len() != m { y.len() } else { out.len() } });
        }
        let norm = &self.model.normalisation;
        let inv_scale = 1.0 / norm.task_scale;
        let mut state = [0.0 as Real; MT];
        for ((dst, v), o) in state.iter_mut().zip(y).zip(norm.task_offset.iter()) {
            *dst = ((v - o) * inv_scale) as Real;
        }
        let kernel = self.model.task_kernel;
        let sign: Real = if direction == Direction::Forward { 1.0 } else { -1.0 };
        let block = self.model.n_points as usize * self.dims.sample_len();
        let trajectory: &[Real] = self.trajectory;
        let (weights, expansion) = (self.weights, self.model.expansion.as_ref());
        let (stage_len, joint_len) = expansion.map_or((0, 0), |e| (e.stage_len(self.dims.n, m), e.n_joint_features as usize * self.dims.n));
        let task_orders = self.orders.task;
        let state = state.get_mut(..m).ok_or(Error::Internal)?;
        flow_along_stages(self.model.integrator, direction, state, |stage, s, rate| {
            let w = match expansion {
                None => task_velocity(shape, &kernel, s, trajectory.get(stage * block..(stage + 1) * block).ok_or(Error::Internal)?),
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
        for ((dst, v), o) in out.iter_mut().zip(state.iter()).zip(norm.task_offset.iter()) {
            *dst = o + norm.task_scale * to_f64(*v);
        }
        if out.iter().all(|v| v.is_finite()) {
            Ok(())
        } else {
            Err(Error::NonFiniteResult)
        }
    }

    #[inline(always)]
    fn joint_flow_shaped<S: Shape>(&mut self, shape: S, x: &[f64], direction: Direction, out: &mut [f64]) -> Result<(), Error> {
        let (m, n) = (self.dims.m, self.dims.n);
        if x.len() != n || out.len() != n {
            return Err(Error::QueryDimension { expected: n, found: if x.len() != n { x.len() } else { out.len() } });
        }
        let mut state = [0.0 as Real; NJ];
        for (dst, v) in state.iter_mut().zip(x) {
            *dst = *v as Real;
        }
        let kernel = self.model.joint_kernel.for_flow(self.model.momentum_law);
        let features: &[Real] = self.features;
        let sign: Real = if direction == Direction::Forward { 1.0 } else { -1.0 };
        let block = self.model.n_points as usize * self.dims.sample_len();
        let trajectory: &[Real] = self.trajectory;
        let (weights, expansion) = (self.weights, self.model.expansion.as_ref());
        let (stage_len, joint_len) = expansion.map_or((0, 0), |e| (e.stage_len(n, m), e.n_joint_features as usize * n));
        // The expansion's joint basis at the moving x goes to the queries' working space.
        let rows_len = expansion.map_or(0, |e| e.n_joint_features as usize * joint_row_len(n));
        let joint_orders = self.orders.joint;
        let rows = self.work.get_mut(..rows_len).ok_or(Error::Internal)?;
        let state = state.get_mut(..n).ok_or(Error::Internal)?;
        flow_along_stages(self.model.integrator, direction, state, |stage, s, rate| {
            let v = match expansion {
                None => {
                    joint_velocity(shape, &kernel, s, features, trajectory.get(stage * block..(stage + 1) * block).ok_or(Error::Internal)?)
                }
                Some(e) => {
                    let (c, _) = stage_weights(weights, stage, stage_len, joint_len).ok_or(Error::Internal)?;
                    let mut xx = [0.0; NJ];
                    for (dst, src) in xx.iter_mut().zip(s).take(n) {
                        *dst = to_f64(*src);
                    }
                    write_joint_basis_with_orders(
                        &self.model.joint_kernel,
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
    pub fn inverse_flow_start(&mut self, target: &[f64], seed: &[f64], out: &mut [f64], nominal_iterations: usize) -> Result<(), Error> {
        let (m, n) = (self.dims.m, self.dims.n);
        if seed.len() != n || out.len() != n {
            return Err(Error::QueryDimension { expected: n, found: if seed.len() != n { seed.len() } else { out.len() } });
        }
        let mut pulled = [0.0; MT];
        let pulled = pulled.get_mut(..m).ok_or(Error::Internal)?;
        self.task_flow(target, Direction::Backward, pulled)?;
        let mut nominal = [0.0; NJ];
        let nominal = nominal.get_mut(..n).ok_or(Error::Internal)?;
        let scale = self.model.normalisation.task_scale;
        // k0⁻¹ of tool point 0, the point `evaluate` gives (the model itself without tool points).
        crate::kinematics::with_tool_point(&self.model.nominal, 0, |k0| {
            crate::inverse_kinematics::nominal_position(k0, pulled, seed, nominal, nominal_iterations, scale)
        })
        .flatten()
        .ok_or(Error::NonFiniteResult)?;
        self.joint_flow(nominal, Direction::Forward, out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_backward_pass_reads_the_stages_in_reverse() {
        let total = 10;
        let forward: [usize; 10] = core::array::from_fn(|g| stored_stage(Direction::Forward, total, g));
        let backward: [usize; 10] = core::array::from_fn(|g| stored_stage(Direction::Backward, total, g));
        assert_eq!(forward, [0, 1, 2, 3, 4, 5, 6, 7, 8, 9]);
        assert_eq!(backward, [9, 8, 7, 6, 5, 4, 3, 2, 1, 0]);
    }
}

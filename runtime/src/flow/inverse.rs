//! The inverse flows' pieces on the kernel form (issue 15, docs/DESIGN.md §10): the direction a
//! flow is integrated in, the velocities w(y) and v(x) from one stage's stored samples (without
//! their Jacobians), and the integration along the stored stages — reversed when backward, so each
//! step of the scheme runs on the same stages as forward, mirrored. `crate::flow_maps` composes
//! them into ψ, φ, their inverses and compensation's start k1⁻¹ = φ ∘ k0⁻¹ ∘ ψ⁻¹.

use crate::error::Error;
use crate::flow::Shape;
use crate::integrate::integrate_checked;
use crate::kernel::{joint_features, joint_kernel_parts_n, FEATURES_PER_JOINT};
use crate::real::{exp, to_f64, Real};
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
pub(crate) fn task_velocity<S: Shape>(shape: S, kernel: &TaskKernel, y: &[Real], samples: &[Real]) -> [Real; MT] {
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
pub(crate) fn joint_velocity<S: Shape>(shape: S, kernel: &JointKernel, x: &[Real], features: &[Real], samples: &[Real]) -> [Real; NJ] {
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
pub(crate) fn flow_along_stages(
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

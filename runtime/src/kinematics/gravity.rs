//! Gravity torques of a mass model on the rigid chain and their first and second derivatives.
//!
//! ```text
//! V(q) = Σ_k g·(m_k o_k(q) + R_k(q) s_k)        τ = ∂V/∂q  (the gravity regressor: linear in m_k, s_k)
//! ```
//!
//! o_k, R_k: origin and rotation of link k's own frame (at its distal end); m_k its mass, s_k = m_k r_k
//! its first moment (r_k the centre of mass in that frame). w_k = R_k s_k is a vector carried by
//! every joint up to k, so it enters the column sums exactly as the points do (∂w/∂q_a = z_a × w,
//! 0 for a prismatic joint) and the derivative formulas of [`crate::kinematics::augmented`] hold unchanged.
//! The point-mass model of `[gravity] link_masses` is s_k = 0; a [`cbd_protocol::Effect::GravityMoment`]
//! is one link's (m, s) felt by one joint.
//!
//! f64 through `libm`, no fused multiply-add, no panic path.

use crate::kinematics::chain::{at, at2, gravity_vector, sorted3, Chain, Order};
use crate::kinematics::spatial::{add_scaled, dot, V3, ZERO};
use cbd_protocol::{GravityModel, NominalModel, MAX_JOINTS as NJ};

/// The gravity torques τ = ∇V and their derivatives (V(q) = Σ_k g·(m_k o_k(q) + R_k(q) s_k)), joint order.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GravityTerms {
    /// τ_j = ∂V/∂q_j.
    pub tau: [f64; NJ],
    /// `[j][e]`: ∂²V/∂q_j∂q_e (order ≥ `First`).
    pub d_tau: [[f64; NJ]; NJ],
    /// `[j][e][d]`: ∂³V/∂q_j∂q_e∂q_d (order `Second`).
    pub d2_tau: [[[f64; NJ]; NJ]; NJ],
}

impl GravityTerms {
    pub(crate) const ZERO: GravityTerms = GravityTerms { tau: [0.0; NJ], d_tau: [[0.0; NJ]; NJ], d2_tau: [[[0.0; NJ]; NJ]; NJ] };
}

/// w = R s: a vector given in a link's own frame (rows of R), in the base frame.
#[inline(always)]
fn rotate(rows: &[V3; 3], s: &V3) -> V3 {
    [dot(rows[0], *s), dot(rows[1], *s), dot(rows[2], *s)]
}

/// τ, Dτ, D²τ of the mass model `moment_of(k) = (m_k, s_k)` (s_k in link k's own frame).
pub(crate) fn gravity_of(chain: &Chain, g: &V3, moment_of: impl Fn(usize) -> (f64, V3), order: Order) -> GravityTerms {
    let n = chain.n;
    let mut out = GravityTerms::ZERO;
    // w_k = R_k s_k: the first moments in the base frame (carried by every joint up to k).
    let mut first_moments = [ZERO; NJ];
    let mut masses = [0.0; NJ];
    for (k, (w, m)) in first_moments.iter_mut().zip(masses.iter_mut()).enumerate().take(n) {
        let (m_k, s_k) = moment_of(k);
        *m = m_k;
        if s_k != ZERO {
            *w = rotate(&at(&chain.rotations, k), &s_k);
        }
    }
    // col_c = Σ_{k ≥ c} (m_k ∂o_k/∂q_c + ∂w_k/∂q_c): what joint c does to the link moments (V's gradient is g·col).
    let mut col = [ZERO; NJ];
    for (c, col_c) in col.iter_mut().enumerate().take(n) {
        for (k, end) in chain.ends.iter().enumerate().take(n).skip(c) {
            add_scaled(col_c, chain.point_rate(c, end), at(&masses, k));
            let w_k = at(&first_moments, k);
            if w_k != ZERO {
                let rate = chain.carry(c, &w_k);
                add_scaled(col_c, rate, 1.0);
            }
        }
    }
    // τ_c = ∂V/∂q_c = g·col_c
    for (t, col_c) in out.tau.iter_mut().zip(col.iter()).take(n) {
        *t = dot(*g, *col_c);
    }
    if order == Order::Value {
        return out;
    }
    let mut dual = [ZERO; NJ];
    for (a, d) in dual.iter_mut().enumerate().take(n) {
        *d = chain.gravity_dual(a, g);
    }
    // ∂²V/∂q_a∂q_b = g·(z_a × col_b) = gz_a·col_b for a ≤ b
    for (j, row) in out.d_tau.iter_mut().enumerate().take(n) {
        for (e, v) in row.iter_mut().enumerate().take(n) {
            let (a, b) = (j.min(e), j.max(e));
            *v = dot(at(&dual, a), at(&col, b));
        }
    }
    if order == Order::First {
        return out;
    }
    // carried[b][c] = ∂col_c/∂q_b = z_b × col_c for b ≤ c (prismatic b: 0)
    let mut carried = [[ZERO; NJ]; NJ];
    for (b, row) in carried.iter_mut().enumerate().take(n) {
        for (c, v) in row.iter_mut().enumerate().take(n).skip(b) {
            *v = chain.carry(b, &at(&col, c));
        }
    }
    // ∂³V/∂q_a∂q_b∂q_c = g·(z_a × (z_b × col_c)) = gz_a·carried[b][c] for sorted a ≤ b ≤ c
    for (i, plane) in out.d2_tau.iter_mut().enumerate().take(n) {
        for (j, row) in plane.iter_mut().enumerate().take(n) {
            for (k, v) in row.iter_mut().enumerate().take(n) {
                let (a, b, c) = sorted3(i, j, k);
                *v = dot(at(&dual, a), at2(&carried, b, c));
            }
        }
    }
    out
}

/// Gravity torques τ_j(q) = ∂V/∂q_j of the rigid chain of `model` under its gravity/mass model,
/// and (with `order`) their first and second derivatives.
pub fn gravity_terms(model: &NominalModel, q: &[f64], order: Order) -> GravityTerms {
    let gravity = &model.effects().gravity;
    gravity_of(&Chain::of(model, q), &gravity_vector(model, gravity), point_masses(gravity), order)
}

/// The point-mass model of `[gravity]`: m_k = `link_masses[k]` (1 when the list is empty) at the
/// origin of link k's frame, s_k = 0.
pub(crate) fn point_masses(gravity: &GravityModel) -> impl Fn(usize) -> (f64, V3) + '_ {
    move |k| (gravity.link_masses.get(k).copied().unwrap_or(1.0), ZERO)
}

/// One link's moment set: (m, s) at `link`, nothing elsewhere.
pub(crate) fn one_link(link: usize, mass: f64, first_moment: V3) -> impl Fn(usize) -> (f64, V3) {
    move |k| if k == link { (mass, first_moment) } else { (0.0, ZERO) }
}

/// τ_j(q) = ∂V/∂q_j, V(q) = Σ_k m_k g·o_k(q) (the point-mass model): the gravity torques of the rigid chain of `model`.
pub fn gravity_torques(model: &NominalModel, q: &[f64]) -> [f64; NJ] {
    gravity_terms(model, q, Order::Value).tau
}

#[cfg(test)]
#[allow(clippy::needless_range_loop)]
mod tests {
    extern crate std;
    use super::*;
    use crate::kinematics::augmented::tests::{check_gravity_terms, close, config, fd, models};
    use std::format;

    /// A mass distribution off the link ends: m_k and s_k = m_k r_k, different per link.
    fn moments(k: usize) -> (f64, V3) {
        let m = [3.7, 8.4, 2.3, 1.2, 1.2, 0.2, 0.5][k];
        (m, [m * (0.1 - 0.07 * k as f64), m * 0.02 * k as f64, m * (-0.05 + 0.01 * k as f64)])
    }

    /// V(q) = Σ_k g·(m_k o_k + R_k s_k), with R_k from the frame walk.
    fn potential_with_moments(model: &NominalModel, q: &[f64]) -> f64 {
        let chain = Chain::of(model, q);
        let g = gravity_vector(model, &model.effects().gravity);
        (0..chain.n)
            .map(|k| {
                let (m, s) = moments(k);
                let r = &chain.rotations[k];
                let w = [dot(r[0], s), dot(r[1], s), dot(r[2], s)];
                m * dot(g, chain.ends[k]) + dot(g, w)
            })
            .sum()
    }

    #[test]
    fn torques_of_off_end_masses_and_their_derivatives_match_finite_differences() {
        for (name, model) in models() {
            let n = model.n_joints();
            let g = gravity_vector(&model, &model.effects().gravity);
            let terms = |x: &[f64], order| gravity_of(&Chain::of(&model, x), &g, moments, order);
            for seed in 1..4 {
                let q = config(n, seed);
                let q = &q[..n];
                let t = terms(q, Order::Second);
                let scale = 1.0 + t.tau.iter().fold(0.0f64, |a, v| a.max(v.abs()));
                // The first moments matter: the torques differ from those of the masses alone.
                let alone = gravity_of(&Chain::of(&model, q), &g, |k| (moments(k).0, ZERO), Order::Value).tau;
                assert!((0..n).any(|j| (alone[j] - t.tau[j]).abs() > 1e-3 * scale), "{name}: {alone:?} vs {:?}", t.tau);
                check_gravity_terms(name, q, |x| potential_with_moments(&model, x), &terms);
            }
        }
    }

    #[test]
    fn link_frames_are_rotations_that_move_with_their_link() {
        // R_k orthonormal, and o_k + R_k x is a point of link k: its rate is z_a × (p − o_a).
        for (name, model) in models() {
            let n = model.n_joints();
            let q = config(n, 5);
            let q = &q[..n];
            let chain = Chain::of(&model, q);
            let x = [0.3, -0.2, 0.7];
            let point = |c: &Chain, k: usize| {
                let r = &c.rotations[k];
                let w = [dot(r[0], x), dot(r[1], x), dot(r[2], x)];
                [c.ends[k][0] + w[0], c.ends[k][1] + w[1], c.ends[k][2] + w[2]]
            };
            for k in 0..n {
                let r = &chain.rotations[k];
                for a in 0..3 {
                    for b in 0..3 {
                        let rtr: f64 = (0..3).map(|i| r[i][a] * r[i][b]).sum();
                        assert!((rtr - if a == b { 1.0 } else { 0.0 }).abs() < 1e-12, "{name} R_{k}");
                    }
                }
                for d in 0..n {
                    let rate = fd(q, d, 1e-6, |y| point(&Chain::of(&model, y), k));
                    let exact = if d <= k { chain.point_rate(d, &point(&chain, k)) } else { ZERO };
                    for c in 0..3 {
                        close(&format!("{name} point of link {k} along q{d}"), rate[c], exact[c], 1.0, 1e-8);
                    }
                }
            }
        }
    }
}

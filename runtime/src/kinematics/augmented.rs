//! Physical effects on top of the rigid nominal chain ([`cbd_protocol::Effects`]): the augmented
//! kinematics and its Jacobian, and the effect terms δ, b to second order that its Hessian
//! (`augmented_derivatives`) builds on.
//!
//! ```text
//! k0_aug(q)   = k_rigid(s) + b(q),                      s = q + δ(q),  A = I + Dδ(q)
//! Dk0_aug(q)  = Dk_rigid(s) A + Db(q)
//! D²k0_aug(q) = D²k_rigid(s)[A·, A·] + Dk_rigid(s) D²δ(q) + D²b(q)
//! ```
//!
//! Joint deflections δ_j: `EncoderScale` scale·q_j; `Transmission` cos·cos(h q_j) + sin·sin(h q_j);
//! `GravityCompliance` compliance·τ_j(q) with τ = ∇V, V(q) = Σ_k m_k g·c_k(q) on the rigid chain at
//! the commanded q (c_k the distal end of link k, m_k = `link_masses[k]` or 1 when the list is
//! empty). Task-space bending b: `LinkBending` compliance·(g − (g·u)u), u the unit vector from
//! the start of link k to its end (the start of link 0 is the base origin).
//!
//! Derivatives of the chain's geometry: joint a carries every point and vector distal to it. For
//! a vector w carried by the links after joint a, ∂w/∂q_a = z_a × w (revolute) or 0 (prismatic);
//! for a point c after joint a, ∂c/∂q_a = z_a × (c − o_a) or z_a. Axis z_b and point o_b of a
//! later joint are themselves carried by joint a, so for sorted a ≤ b ≤ c (revolute joints)
//! ∂³c/∂q_a∂q_b∂q_c = z_a × (z_b × (z_c × (c − o_c))), and prismatic joints give z or 0 accordingly.
//!
//! Everything is f64 through `libm`, with no fused multiply-add: host and firmware agree bit for
//! bit. Out-of-range joint or link indices (rejected by validation) are ignored, never a panic.

pub use crate::kinematics::chain::Order;
use crate::kinematics::chain::{at, at2, gravity_vector, Chain};
use crate::kinematics::gravity::{gravity_of, one_link, point_masses};
pub use crate::kinematics::gravity::{gravity_terms, gravity_torques, GravityTerms};
use crate::kinematics::rigid::Kinematics;
use crate::kinematics::rigid_derivatives::NominalHessian;
use crate::kinematics::spatial::{add_scaled, dot, scale, sub, V3, ZERO};
use cbd_protocol::{DhChain, Effect, Effects, NominalModel, MAX_JOINTS as NJ, MAX_TASK_DIM as MT};

/// δ(q), b(q) and their derivatives for a list of effects.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EffectTerms {
    /// δ_j: joint deflection.
    pub delta: [f64; NJ],
    /// `[j][e]`: ∂δ_j/∂q_e.
    pub d_delta: [[f64; NJ]; NJ],
    /// `[j][e][d]`: ∂²δ_j/∂q_e∂q_d.
    pub d2_delta: [[[f64; NJ]; NJ]; NJ],
    /// b: task-space displacement (first `task_dim` entries).
    pub b: [f64; MT],
    /// `[a][d]`: ∂b_a/∂q_d.
    pub d_b: [[f64; NJ]; MT],
    /// `[a][e][d]`: ∂²b_a/∂q_e∂q_d.
    pub d2_b: NominalHessian,
}

impl EffectTerms {
    const ZERO: EffectTerms = EffectTerms {
        delta: [0.0; NJ],
        d_delta: [[0.0; NJ]; NJ],
        d2_delta: [[[0.0; NJ]; NJ]; NJ],
        b: [0.0; MT],
        d_b: [[0.0; NJ]; MT],
        d2_b: [[[0.0; NJ]; NJ]; MT],
    };
}

/// b += κ (g − (g·u) u) for link k, u = v/|v|, v = c_k − c_{k−1}, and its derivatives:
/// ∂b = −κ((g·∂u) u + (g·u) ∂u), ∂_e∂_d b = −κ((g·u_ed) u + (g·u_d) u_e + (g·u_e) u_d + (g·u) u_ed),
/// u_d = P v_d / r, u_ed = (P v_ed − u_d (u·v_e) − u_e (u·v_d) − u (u_d·v_e)) / r, P = I − u uᵀ.
fn add_bending(chain: &Chain, g: &V3, link: usize, compliance: f64, order: Order, out: &mut EffectTerms) {
    let n = chain.n;
    if link >= n {
        return;
    }
    let end = at(&chain.ends, link);
    let start = if link == 0 { chain.start } else { at(&chain.ends, link - 1) };
    let v = sub(end, start);
    let r = libm::sqrt(dot(v, v));
    if r.is_nan() || r <= 0.0 {
        return;
    }
    let inv = 1.0 / r;
    let u = scale(v, inv);
    let gu = dot(*g, u);
    // b = κ (g − (g·u) u)
    for (b, (g_c, u_c)) in out.b.iter_mut().zip(g.iter().zip(u.iter())) {
        *b += compliance * (g_c - gu * u_c);
    }
    if order == Order::Value {
        return;
    }
    // v_d = ∂v/∂q_d: joints before the link carry v; joint `link` moves its end only.
    let mut v_d = [ZERO; NJ];
    for (d, vd) in v_d.iter_mut().enumerate().take(link + 1) {
        *vd = if d < link { chain.carry(d, &v) } else { chain.point_rate(d, &end) };
    }
    // u_d = P v_d / r
    let mut u_d = [ZERO; NJ];
    for (ud, vd) in u_d.iter_mut().zip(v_d.iter()).take(link + 1) {
        let mut p = *vd;
        add_scaled(&mut p, u, -dot(u, *vd));
        *ud = scale(p, inv);
    }
    // ∂_d b = −κ ((g·u_d) u + (g·u) u_d)
    for (d, ud) in u_d.iter().enumerate().take(link + 1) {
        let gud = dot(*g, *ud);
        for (row, (u_c, ud_c)) in out.d_b.iter_mut().zip(u.iter().zip(ud.iter())) {
            if let Some(slot) = row.get_mut(d) {
                *slot -= compliance * (gud * u_c + gu * ud_c);
            }
        }
    }
    if order == Order::First {
        return;
    }
    for e in 0..=link {
        for d in 0..=link {
            // v_ed = ∂_min v_max = carry(min, v_max) (the later derivative is carried by the earlier joint)
            let (lo, hi) = (e.min(d), e.max(d));
            let v_ed = chain.carry(lo, &at(&v_d, hi));
            let (ue, ud, ve, vd) = (at(&u_d, e), at(&u_d, d), at(&v_d, e), at(&v_d, d));
            let mut w = v_ed;
            add_scaled(&mut w, u, -dot(u, v_ed));
            add_scaled(&mut w, ud, -dot(u, ve));
            add_scaled(&mut w, ue, -dot(u, vd));
            add_scaled(&mut w, u, -dot(ud, ve));
            let u_ed = scale(w, inv);
            let (gued, gud, gue) = (dot(*g, u_ed), dot(*g, ud), dot(*g, ue));
            for (plane, c) in out.d2_b.iter_mut().zip(0..3) {
                let value = gued * at(&u, c) + gud * at(&ue, c) + gue * at(&ud, c) + gu * at(&u_ed, c);
                if let Some(slot) = plane.get_mut(e).and_then(|row| row.get_mut(d)) {
                    *slot -= compliance * value;
                }
            }
        }
    }
}

/// δ(q), b(q) and (with `order`) their derivatives for `effects` on the rigid chain of `model`
/// under its gravity/mass model (`model`'s own effect list is not used).
pub fn effect_terms(model: &NominalModel, effects: &[Effect], q: &[f64], order: Order) -> EffectTerms {
    let mut out = EffectTerms::ZERO;
    let n = model.n_joints().min(q.len()).min(NJ);
    let needs_chain =
        effects.iter().any(|e| matches!(e, Effect::GravityCompliance { .. } | Effect::LinkBending { .. } | Effect::GravityMoment { .. }));
    let chain = if needs_chain { Chain::of(model, q) } else { Chain::of(model, &[]) };
    let gravity = &model.effects().gravity;
    let g = gravity_vector(model, gravity);
    let gravity_terms = if effects.iter().any(|e| matches!(e, Effect::GravityCompliance { .. })) {
        gravity_of(&chain, &g, point_masses(gravity), order)
    } else {
        GravityTerms::ZERO
    };
    for effect in effects {
        match *effect {
            Effect::EncoderScale { joint, scale } => {
                let j = joint as usize;
                if j >= n {
                    continue;
                }
                // δ_j = scale·q_j, ∂_j δ_j = scale
                if let Some(delta) = out.delta.get_mut(j) {
                    *delta += scale * at(q, j);
                }
                if let Some(slot) = out.d_delta.get_mut(j).and_then(|row| row.get_mut(j)) {
                    *slot += scale;
                }
            }
            Effect::Transmission { joint, harmonic, cos, sin } => {
                let j = joint as usize;
                if j >= n {
                    continue;
                }
                let h = harmonic as f64;
                let hq = h * at(q, j);
                let (s, c) = (libm::sin(hq), libm::cos(hq));
                // δ_j = cos·cos(h q_j) + sin·sin(h q_j)
                if let Some(delta) = out.delta.get_mut(j) {
                    *delta += cos * c + sin * s;
                }
                // ∂_j δ_j = h (sin·cos(h q_j) − cos·sin(h q_j))
                if let Some(slot) = out.d_delta.get_mut(j).and_then(|row| row.get_mut(j)) {
                    *slot += h * (sin * c - cos * s);
                }
                // ∂²_j δ_j = −h² (cos·cos(h q_j) + sin·sin(h q_j))
                if let Some(slot) = out.d2_delta.get_mut(j).and_then(|p| p.get_mut(j)).and_then(|row| row.get_mut(j)) {
                    *slot -= h * h * (cos * c + sin * s);
                }
            }
            Effect::GravityCompliance { joint, compliance } => {
                let j = joint as usize;
                if j >= n {
                    continue;
                }
                add_gravity_row(&mut out, &gravity_terms, j, compliance, order);
            }
            Effect::LinkBending { link, compliance } => add_bending(&chain, &g, link as usize, compliance, order, &mut out),
            Effect::GravityMoment { joint, link, mass, first_moment } => {
                let j = joint as usize;
                if j >= n {
                    continue;
                }
                // δ_j += ∂_j g·(m o_k + R_k s), its derivatives likewise (compliance 1: the gauge)
                let t = gravity_of(&chain, &g, one_link(link as usize, mass, first_moment), order);
                add_gravity_row(&mut out, &t, j, 1.0, order);
            }
        }
    }
    out
}

/// δ_j += κ τ_j, ∂δ_j += κ ∂τ_j, ∂²δ_j += κ ∂²τ_j.
fn add_gravity_row(out: &mut EffectTerms, terms: &GravityTerms, j: usize, compliance: f64, order: Order) {
    if let Some(delta) = out.delta.get_mut(j) {
        *delta += compliance * at(&terms.tau, j);
    }
    if order == Order::Value {
        return;
    }
    if let (Some(dst), Some(src)) = (out.d_delta.get_mut(j), terms.d_tau.get(j)) {
        for (o, t) in dst.iter_mut().zip(src.iter()) {
            *o += compliance * t;
        }
    }
    if order == Order::Second {
        if let (Some(dst), Some(src)) = (out.d2_delta.get_mut(j), terms.d2_tau.get(j)) {
            for (o_row, t_row) in dst.iter_mut().zip(src.iter()) {
                for (o, t) in o_row.iter_mut().zip(t_row.iter()) {
                    *o += compliance * t;
                }
            }
        }
    }
}

/// `model`'s chain without its effects.
pub(crate) fn without_effects(model: &NominalModel) -> NominalModel {
    match model {
        NominalModel::PlanarChain { lengths, .. } => NominalModel::PlanarChain { lengths: lengths.clone(), effects: Effects::NONE_PLANAR },
        NominalModel::DhChain(c) => NominalModel::DhChain(DhChain {
            convention: c.convention,
            joints: c.joints.clone(),
            base: c.base,
            tool: c.tool,
            effects: Effects::NONE,
            tool_points: c.tool_points.clone(),
        }),
    }
}

/// k_rigid(q) and Dk_rigid(q): the chain alone, its effects ignored (evaluated by the effect-free
/// code path, [`crate::kinematics::rigid::kinematics`], so that the rigid part is the same arithmetic either way).
pub fn rigid_kinematics(model: &NominalModel, q: &[f64]) -> Kinematics {
    crate::kinematics::rigid::kinematics(&without_effects(model), q)
}

/// s = q + δ(q) (first `n` entries).
pub(crate) fn deflected(q: &[f64], t: &EffectTerms, n: usize) -> [f64; NJ] {
    let mut s = [0.0; NJ];
    for ((dst, q_i), d) in s.iter_mut().zip(q.iter()).zip(t.delta.iter()).take(n) {
        *dst = q_i + d;
    }
    s
}

/// k0_aug(q) = k_rigid(q + δ(q)) + b(q) and Dk0_aug = Dk_rigid(s)(I + Dδ) + Db, model units.
/// (Out of line: the effect-free path of `kinematics::forward_kinematics` keeps its code and cost.)
#[inline(never)]
#[cold]
pub fn kinematics(model: &NominalModel, q: &[f64]) -> Kinematics {
    let n = model.n_joints().min(q.len()).min(NJ);
    let m = model.task_dim();
    let t = effect_terms(model, &model.effects().list, q, Order::First);
    let s = deflected(q, &t, n);
    let rigid = crate::kinematics::rigid::kinematics(&without_effects(model), s.get(..n).unwrap_or(&[]));
    let mut out = rigid;
    for (a, ((p, b), (row, rigid_row))) in
        out.position.iter_mut().zip(t.b.iter()).zip(out.jacobian.iter_mut().zip(rigid.jacobian.iter())).enumerate()
    {
        if a >= m {
            break;
        }
        *p += b;
        // Dk0_aug[a][e] = Dk[a][e] + Σ_i Dk[a][i] Dδ[i][e] + Db[a][e]
        for (e, v) in row.iter_mut().enumerate().take(n) {
            let mut acc = 0.0;
            for (jac_ai, dd_i) in rigid_row.iter().zip(t.d_delta.iter()).take(n) {
                acc += jac_ai * at(dd_i, e);
            }
            *v += acc + at2(&t.d_b, a, e);
        }
    }
    out
}

#[cfg(test)]
#[allow(clippy::needless_range_loop)]
pub(crate) mod tests {
    extern crate std;
    use super::*;
    use crate::flow::query_derivatives::nominal_hessian;
    use crate::kinematics::forward_kinematics;
    use cbd_protocol::{DhChain, DhJoint, Effects, Transform};
    use cbd_protocol::{DhConvention, GravityModel, JointKind};
    use heapless::Vec as HVec;
    use std::format;

    fn all_effects(n: usize, gravity: GravityModel) -> Effects {
        let mut list = HVec::new();
        for j in 0..n as u8 {
            let f = 1.0 + j as f64;
            list.push(Effect::EncoderScale { joint: j, scale: 0.01 * f }).unwrap();
            list.push(Effect::Transmission { joint: j, harmonic: 1 + j % 3, cos: 0.02 / f, sin: -0.015 }).unwrap();
            list.push(Effect::GravityCompliance { joint: j, compliance: 0.03 / f }).unwrap();
            list.push(Effect::LinkBending { link: j, compliance: 0.02 * f }).unwrap();
            let link = (j + 1).min(n as u8 - 1);
            list.push(Effect::GravityMoment { joint: j, link, mass: 0.3 / f, first_moment: [0.05 * f, -0.02, 0.03] }).unwrap();
        }
        Effects { gravity, list }
    }

    fn rr() -> NominalModel {
        let mut m = NominalModel::planar(&[1.0, 0.5]).unwrap();
        *m.effects_mut() = all_effects(2, GravityModel::PLANAR);
        m
    }

    /// A 6-joint chain with a prismatic joint, metres, tilted gravity and uneven masses.
    fn six(convention: DhConvention) -> NominalModel {
        let j = |kind, a, alpha: f64, d| DhJoint { kind, a, alpha, d, theta_offset: 0.1 };
        let mut tool = Transform::IDENTITY;
        tool.translation = [0.01, 0.02, 0.031];
        let (s, c) = (libm::sin(0.3), libm::cos(0.3));
        let gravity =
            GravityModel { direction: [s * 0.6, s * 0.8, -c], link_masses: HVec::from_slice(&[3.7, 8.4, 2.3, 1.2, 1.2, 0.2]).unwrap() };
        NominalModel::DhChain(DhChain {
            convention,
            joints: HVec::from_slice(&[
                j(JointKind::Revolute, 0.0, core::f64::consts::FRAC_PI_2, 0.089),
                j(JointKind::Revolute, -0.425, 0.0, 0.0),
                j(JointKind::Prismatic, -0.392, 0.2, 0.05),
                j(JointKind::Revolute, 0.0, core::f64::consts::FRAC_PI_2, 0.109),
                j(JointKind::Revolute, 0.03, -core::f64::consts::FRAC_PI_2, 0.094),
                j(JointKind::Revolute, 0.0, 0.0, 0.082),
            ])
            .unwrap(),
            base: Transform { rotation: [0.0, -1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0], translation: [0.1, 0.0, 0.2] },
            tool,
            effects: all_effects(6, gravity),
            tool_points: HVec::new(),
        })
    }

    pub(crate) fn models() -> [(&'static str, NominalModel); 3] {
        [("rr", rr()), ("dh-standard", six(DhConvention::Standard)), ("dh-modified", six(DhConvention::Modified))]
    }

    pub(crate) fn config(n: usize, seed: u64) -> [f64; NJ] {
        let mut s = seed;
        let mut q = [0.0; NJ];
        for v in q.iter_mut().take(n) {
            s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            *v = ((s >> 11) as f64 / (1u64 << 53) as f64) * 6.0 - 3.0;
        }
        q
    }

    fn potential(model: &NominalModel, q: &[f64]) -> f64 {
        let chain = Chain::of(model, q);
        let gravity = &model.effects().gravity;
        let g = gravity_vector(model, gravity);
        (0..chain.n).map(|k| gravity.link_masses.get(k).copied().unwrap_or(1.0) * dot(g, chain.ends[k])).sum()
    }

    /// Central difference of `f` along joint d.
    pub(crate) fn fd<const L: usize>(q: &[f64], d: usize, h: f64, f: impl Fn(&[f64]) -> [f64; L]) -> [f64; L] {
        let (mut a, mut b) = (q.to_vec(), q.to_vec());
        a[d] += h;
        b[d] -= h;
        let (fa, fb) = (f(&a), f(&b));
        core::array::from_fn(|i| (fa[i] - fb[i]) / (2.0 * h))
    }

    pub(crate) fn close(what: &str, fd: f64, exact: f64, scale: f64, tol: f64) -> f64 {
        let err = (fd - exact).abs() / scale;
        assert!(err < tol, "{what}: fd {fd} vs {exact} (relative error {err:e})");
        err
    }

    /// τ, Dτ and D²τ of `terms` at `q` against central differences of `potential` and of `terms`
    /// itself (relative to 1 + max |τ|, within 1e-8).
    pub(crate) fn check_gravity_terms(
        name: &str,
        q: &[f64],
        potential: impl Fn(&[f64]) -> f64,
        terms: impl Fn(&[f64], Order) -> GravityTerms,
    ) {
        let n = q.len();
        let t = terms(q, Order::Second);
        let scale = 1.0 + t.tau.iter().fold(0.0f64, |a, v| a.max(v.abs()));
        for d in 0..n {
            let v = fd(q, d, 1e-5, |x| [potential(x)]);
            close(&format!("{name} tau {d}"), v[0], t.tau[d], scale, 1e-8);
            let dt = fd(q, d, 1e-5, |x| terms(x, Order::Value).tau);
            let ddt = fd(q, d, 1e-5, |x| {
                let t = terms(x, Order::First).d_tau;
                core::array::from_fn::<f64, { NJ * NJ }, _>(|i| t[i / NJ][i % NJ])
            });
            for j in 0..n {
                close(&format!("{name} dtau {j} {d}"), dt[j], t.d_tau[j][d], scale, 1e-8);
                for e in 0..n {
                    close(&format!("{name} d2tau {j} {e} {d}"), ddt[j * NJ + e], t.d2_tau[j][e][d], scale, 1e-8);
                }
            }
        }
    }

    #[test]
    fn gravity_torques_and_their_derivatives_match_finite_differences() {
        for (name, model) in models() {
            let n = model.n_joints();
            for seed in 1..4 {
                let q = config(n, seed);
                let q = &q[..n];
                check_gravity_terms(name, q, |x| potential(&model, x), |x, order| gravity_terms(&model, x, order));
            }
        }
    }

    #[test]
    fn augmented_jacobian_and_hessian_match_finite_differences() {
        let (mut worst_j, mut worst_h) = (0.0f64, 0.0f64);
        for (name, model) in models() {
            let (n, m) = (model.n_joints(), model.task_dim());
            for seed in 1..6 {
                let q = config(n, seed);
                let q = &q[..n];
                let k = forward_kinematics(&model, q);
                let h = nominal_hessian(&model, q);
                let scale = 1.0 + k.jacobian.iter().flatten().fold(0.0f64, |a, v| a.max(v.abs()));
                for d in 0..n {
                    let dp = fd(q, d, 1e-6, |x| forward_kinematics(&model, x).position);
                    let dj = fd(q, d, 1e-6, |x| {
                        let j = forward_kinematics(&model, x).jacobian;
                        core::array::from_fn::<f64, { MT * NJ }, _>(|i| j[i / NJ][i % NJ])
                    });
                    for a in 0..m {
                        worst_j = worst_j.max(close(&format!("{name} J[{a}][{d}]"), dp[a], k.jacobian[a][d], scale, 1e-8));
                        for e in 0..n {
                            worst_h = worst_h.max(close(&format!("{name} H[{a}][{e}][{d}]"), dj[a * NJ + e], h[a][e][d], scale, 1e-7));
                            assert_eq!(h[a][e][d], h[a][e][d]);
                        }
                    }
                }
            }
        }
        std::eprintln!(
            "augmented kinematics vs central differences: Jacobian {worst_j:.1e}, Hessian {worst_h:.1e} (relative to 1 + max |J|)"
        );
    }

    #[test]
    fn each_effect_alone_matches_its_definition() {
        // δ and b against the definitions, evaluated by hand on the RR arm.
        let model = NominalModel::planar(&[1.0, 0.5]).unwrap();
        let q = [0.7, -1.9];
        let one = |e: Effect| effect_terms(&model, &[e], &q, Order::Value);
        assert_eq!(one(Effect::EncoderScale { joint: 1, scale: 0.01 }).delta[1], 0.01 * -1.9);
        let t = one(Effect::Transmission { joint: 0, harmonic: 3, cos: 0.01, sin: -0.02 });
        let hq = 3.0 * 0.7;
        assert_eq!(t.delta[0], 0.01 * libm::cos(hq) + -0.02 * libm::sin(hq));
        // g = −y, unit masses: τ1 = −(2 l1 c1 + l2 c12), τ2 = −l2 c12.
        let t = one(Effect::GravityCompliance { joint: 0, compliance: 1.0 });
        let (c1, c12) = (libm::cos(0.7), libm::cos(0.7 - 1.9));
        assert!((t.delta[0] + 2.0 * c1 + 0.5 * c12).abs() < 1e-15, "{:?}", t.delta);
        assert!((gravity_torques(&model, &q)[1] + 0.5 * c12).abs() < 1e-15);
        // A horizontal link bends along gravity; a vertical one does not.
        let t = effect_terms(&model, &[Effect::LinkBending { link: 0, compliance: 0.01 }], &[0.0, 0.4], Order::Value);
        assert_eq!(t.b, [0.0, -0.01, 0.0]);
        let t =
            effect_terms(&model, &[Effect::LinkBending { link: 0, compliance: 0.01 }], &[core::f64::consts::FRAC_PI_2, 0.4], Order::Value);
        assert!(t.b.iter().all(|v| v.abs() < 1e-18), "{:?}", t.b);
    }

    #[test]
    fn without_effects_the_rigid_code_path_is_taken() {
        for (_, model) in models() {
            let n = model.n_joints();
            let mut rigid = model.clone();
            rigid.effects_mut().list.clear();
            let q = config(n, 9);
            let q = &q[..n];
            assert_eq!(forward_kinematics(&rigid, q), rigid_kinematics(&model, q));
            assert_eq!(nominal_hessian(&rigid, q), crate::kinematics::augmented_derivatives::rigid_hessian(&model, q));
            // Effects that are all zero change nothing either (the augmented path, same values).
            let mut zero = model.clone();
            for e in zero.effects_mut().list.iter_mut() {
                match e {
                    Effect::EncoderScale { scale, .. } => *scale = 0.0,
                    Effect::Transmission { cos, sin, .. } => (*cos, *sin) = (0.0, 0.0),
                    Effect::GravityCompliance { compliance, .. } | Effect::LinkBending { compliance, .. } => *compliance = 0.0,
                    Effect::GravityMoment { mass, first_moment, .. } => (*mass, *first_moment) = (0.0, [0.0; 3]),
                }
            }
            let (a, b) = (forward_kinematics(&zero, q), forward_kinematics(&rigid, q));
            assert_eq!(a, b);
            assert_eq!(nominal_hessian(&zero, q), nominal_hessian(&rigid, q));
        }
    }

    mod never_panics {
        use super::*;
        use proptest::prelude::*;

        fn effect() -> impl Strategy<Value = Effect> {
            let index = 0u8..10;
            let value = prop_oneof![4 => -1.0f64..1.0, 1 => prop::num::f64::ANY];
            prop_oneof![
                (index.clone(), value.clone()).prop_map(|(joint, scale)| Effect::EncoderScale { joint, scale }),
                (index.clone(), 0u8..20, value.clone(), value.clone()).prop_map(|(joint, harmonic, cos, sin)| Effect::Transmission {
                    joint,
                    harmonic,
                    cos,
                    sin
                }),
                (index.clone(), value.clone()).prop_map(|(joint, compliance)| Effect::GravityCompliance { joint, compliance }),
                (index.clone(), value.clone()).prop_map(|(link, compliance)| Effect::LinkBending { link, compliance }),
                (index.clone(), index, value.clone(), prop::array::uniform3(value))
                    .prop_map(|(joint, link, mass, first_moment)| { Effect::GravityMoment { joint, link, mass, first_moment } }),
            ]
        }

        proptest! {
            #![proptest_config(ProptestConfig::with_cases(300))]
            #[test]
            fn evaluation_with_random_effects_never_panics(
                which in 0usize..3,
                list in prop::collection::vec(effect(), 0..12),
                direction in prop::array::uniform3(prop_oneof![4 => -1.0f64..1.0, 1 => prop::num::f64::ANY]),
                masses in prop::collection::vec(prop_oneof![4 => 0.0f64..5.0, 1 => prop::num::f64::ANY], 0..8),
                q in prop::collection::vec(prop_oneof![4 => -10.0f64..10.0, 1 => prop::num::f64::ANY], 0..9),
            ) {
                let (_, mut model) = models().into_iter().nth(which).unwrap();
                let effects = model.effects_mut();
                effects.list = HVec::from_slice(&list).unwrap();
                effects.gravity.direction = direction;
                effects.gravity.link_masses = masses.iter().copied().take(NJ).collect();
                let valid = model.effects().validate(model.n_joints()).is_ok();
                let k = forward_kinematics(&model, &q);
                let h = nominal_hessian(&model, &q);
                let _ = (gravity_torques(&model, &q), effect_terms(&model, &list, &q, Order::Second));
                // A valid model at a finite configuration of the right size gives finite values.
                if valid && q.len() == model.n_joints() && q.iter().all(|v| v.is_finite()) {
                    prop_assert!(k.position.iter().chain(k.jacobian.iter().flatten()).all(|v| v.is_finite()), "{k:?}");
                    prop_assert!(h.iter().flatten().flatten().all(|v| v.is_finite()));
                }
            }
        }
    }
}

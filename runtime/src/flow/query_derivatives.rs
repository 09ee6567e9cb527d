//! The exact Jacobian of the calibrated position: the forward-mode derivative of the query flow
//! (eq. 20) with respect to the query configuration ξ, through the same discrete scheme.
//!
//! Eq. (19)'s transported J(1) omits the term D²k·v, so it is not the derivative of k1. Here each
//! joint direction d carries a tangent (δk_d, δJ_d) of the query state:
//!
//! ```text
//! δk' = Dw δk − δJ v − J ∂_d v
//! δJ' = (D²w δk) J + Dw δJ − δJ Dv − J ∂_d Dv
//! δk(0) = ∂_d k0(ξ),  δJ(0) = ∂_d Dk0(ξ)
//! ```
//!
//! and Dk1(ξ)[:, d] = δk_d(1) exactly for the discrete flow (the tangent of a fixed-step explicit
//! scheme is the same scheme applied to the tangent system). With the configuration term (format 8,
//! docs/DESIGN.md §16) w depends on ξ explicitly: δk' gains ∂_d w and Dw includes the term's
//! k-derivative ([`crate::flow::configuration_field`]; Euler × 1 only, whose one stage reads no D²w).

use crate::flow::{position_rates_shaped, task_field_sums, Dims, JointField, Shape, TaskField, TaskHessian};
use crate::kernel::{joint_kernel_parts_n, FEATURES_PER_JOINT};
use crate::real::Real;
use cbd_protocol::{JointKernel, NominalModel, TaskKernel, MAX_JOINTS as NJ, MAX_TASK_DIM as MT};

pub(crate) use super::stage_fields::{joint_sums, StageFields};
pub use super::stage_fields::{kernel_row_len, JointHessian};
pub use crate::kinematics::rigid_derivatives::NominalHessian;

/// Writes the query's kernel rows against every control point (K_V(ξ, x_j), ∇ = K f', and with
/// `hessian` ∂_e ∂_d K_V = K (f'_e f'_d + δ_ed f''_e)) and returns the largest K_V.
/// `fq` are the query's features, `features` the control points' (N × n × 2).
pub fn write_kernel_rows<S: Shape>(
    shape: S,
    kernel: &JointKernel,
    fq: &[[Real; FEATURES_PER_JOINT]; NJ],
    features: &[Real],
    rows: &mut [Real],
    hessian: bool,
) -> Real {
    let n = shape.n();
    let mut support: Real = 0.0;
    let row_len = kernel_row_len(n);
    if n == 0 {
        return support;
    }
    // Walks the feature pairs by splitting (a zip of two `chunks_exact` keeps a division-by-zero
    // panic path the optimiser cannot remove).
    let (mut pairs, _) = features.as_chunks::<FEATURES_PER_JOINT>();
    for r in rows.chunks_exact_mut(row_len.max(1)) {
        let Some((fxj, rest)) = pairs.split_at_checked(n) else { break };
        pairs = rest;
        let (mut first, mut second) = ([0.0; NJ], [0.0; NJ]);
        let k = joint_kernel_parts_n(kernel, n, fq, fxj, &mut first, &mut second);
        let Some((r_k, rest)) = r.split_first_mut() else { return support };
        let Some((r_grad, r_hess)) = rest.split_at_mut_checked(n) else { return support };
        *r_k = k;
        for (dst, f1) in r_grad.iter_mut().zip(first.iter()) {
            *dst = f1 * k;
        }
        if hessian {
            for ((dst_row, f1e), (e, f2e)) in r_hess.chunks_exact_mut(n.max(1)).zip(first.iter()).zip(second.iter().enumerate()) {
                let kf1e = k * f1e;
                for (dst, f1d) in dst_row.iter_mut().zip(first.iter()) {
                    *dst = kf1e * f1d;
                }
                if let Some(diagonal) = dst_row.get_mut(e) {
                    *diagonal += k * f2e;
                }
            }
        }
        // |K_V|: the flow's kernel carries the field's sign.
        support = support.max(if k < 0.0 { -k } else { k });
    }
    support
}

/// Second derivatives of the nominal forward kinematics at `x` (with effects, the augmented
/// D²k0_aug of [`crate::kinematics::augmented_derivatives::hessian`]).
pub fn nominal_hessian(model: &NominalModel, x: &[f64]) -> NominalHessian {
    let mut h = [[[0.0; NJ]; NJ]; MT];
    write_nominal_hessian(model, x, &mut h);
    h
}

/// [`nominal_hessian`] written into `h`, which must hold zeros (no copy of the array on the way).
pub(crate) fn write_nominal_hessian(model: &NominalModel, x: &[f64], h: &mut NominalHessian) {
    if !model.effects().is_empty() {
        *h = crate::kinematics::augmented_derivatives::hessian(model, x);
        return;
    }
    crate::kinematics::rigid_derivatives::write_hessian(model, x, h)
}

/// The rate of one direction's tangent position given the stage's fields:
/// δk' = Dw δk − δJ v − J ∂_d v (first derivatives of the fields only).
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn query_tangent_position_rate<S: Shape>(
    shape: S,
    direction: usize,
    jac: &[[Real; NJ]; MT],
    tf: &TaskField,
    jf: &JointField,
    dk: &[Real; MT],
    djac: &[[Real; NJ]; MT],
    out_dk: &mut [Real],
) {
    let (m, n) = (shape.m(), shape.n());
    // ∂_d v = Dv[:, d]
    let mut dv_d = [0.0; NJ];
    for (dst, dv_f) in dv_d.iter_mut().zip(jf.dv.iter()).take(n) {
        *dst = dv_f.get(direction).copied().unwrap_or(0.0);
    }
    for ((o_k, dw_a), (jac_a, djac_a)) in out_dk.iter_mut().zip(tf.dw.iter()).zip(jac.iter().zip(djac.iter())).take(m) {
        let mut r = 0.0;
        for (w, d) in dw_a.iter().zip(dk.iter()).take(m) {
            r += w * d;
        }
        for ((dj, j), (v, dvd)) in djac_a.iter().zip(jac_a.iter()).zip(jf.v.iter().zip(dv_d.iter())).take(n) {
            r -= dj * v + j * dvd;
        }
        *o_k = r;
    }
}

/// The rate of one direction's tangent Jacobian given the stage's fields and their second derivatives:
/// δJ' = (D²w δk) J + Dw δJ − δJ Dv − J ∂_d Dv.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn query_tangent_jacobian_rate<S: Shape>(
    shape: S,
    jac: &[[Real; NJ]; MT],
    tf: &TaskField,
    t: &TaskHessian,
    jf: &JointField,
    ddv_d: &[[Real; NJ]; NJ],
    dk: &[Real; MT],
    djac: &[[Real; NJ]; MT],
    out_djac: &mut [Real],
) {
    let (m, n) = (shape.m(), shape.n());
    if n == 0 {
        return;
    }
    // (D²w δk)[a][c] = Σ_b T[a][c][b] δk[b]
    let mut d2w = [[0.0; MT]; MT];
    for (d2w_a, t_a) in d2w.iter_mut().zip(t.iter()).take(m) {
        for (v, t_ac) in d2w_a.iter_mut().zip(t_a.iter()).take(m) {
            let mut r = 0.0;
            for (t_acb, dk_b) in t_ac.iter().zip(dk.iter()).take(m) {
                r += t_acb * dk_b;
            }
            *v = r;
        }
    }
    let rows = out_djac.chunks_exact_mut(n.max(1)).zip(tf.dw.iter().zip(d2w.iter())).zip(jac.iter().zip(djac.iter()));
    for ((o_jac, (dw_a, d2w_a)), (jac_a, djac_a)) in rows.take(m) {
        let mut acc = [0.0; NJ];
        for ((d2, w), (jac_c, djac_c)) in d2w_a.iter().zip(dw_a.iter()).zip(jac.iter().zip(djac.iter())).take(m) {
            for (o, (jce, djce)) in acc.iter_mut().zip(jac_c.iter().zip(djac_c.iter())).take(n) {
                *o += d2 * jce + w * djce;
            }
        }
        for ((djf, jf_), (dv_f, ddv_f)) in djac_a.iter().zip(jac_a.iter()).zip(jf.dv.iter().zip(ddv_d.iter())).take(n) {
            for (o, (dv_fe, ddv_fe)) in acc.iter_mut().zip(dv_f.iter().zip(ddv_f.iter())).take(n) {
                *o -= djf * dv_fe + jf_ * ddv_fe;
            }
        }
        for (dst, src) in o_jac.iter_mut().zip(acc.iter()) {
            *dst = *src;
        }
    }
}

/// Length of the query state with its tangents: (k, J) and one (δk, δJ) per joint.
pub const fn query_tangent_len(dims: Dims) -> usize {
    dims.query_len() * (1 + dims.n)
}

/// Copies (k, J) of a query state (`m + m·n` values) into fixed arrays.
#[inline(always)]
fn unpack<S: Shape>(shape: S, state: &[Real]) -> ([Real; MT], [[Real; NJ]; MT]) {
    let (m, n) = (shape.m(), shape.n());
    let (mut k, mut jac) = ([0.0; MT], [[0.0; NJ]; MT]);
    for (dst, src) in k.iter_mut().zip(state.iter()).take(m) {
        *dst = *src;
    }
    if n > 0 {
        for (dst_row, src_row) in jac.iter_mut().zip(state.get(m..).unwrap_or(&[]).chunks_exact(n.max(1))).take(m) {
            for (dst, src) in dst_row.iter_mut().zip(src_row.iter()) {
                *dst = *src;
            }
        }
    }
    (k, jac)
}

/// The task field of the kernel form at one stage ([`crate::flow::task_field_sums`]). Inlined on
/// bare-metal targets and out of line elsewhere, as measured (same bits either way): on the host
/// (x86-64) inlined into the query's rates its per-point sums left the registers (RR Heun × 5
/// evaluate 41 µs against 31 µs); on the Cortex-M out of line cost 5 % (M7 dp) and 27 % (M4 f32).
#[cfg_attr(target_os = "none", inline(always))]
#[cfg_attr(not(target_os = "none"), inline(never))]
fn kernel_task_field<S: Shape, const HESSIAN: bool>(
    shape: S,
    kernel: &TaskKernel,
    k: &[Real],
    samples: &[Real],
) -> (TaskField, TaskHessian) {
    task_field_sums::<_, HESSIAN>(shape, kernel, k, samples)
}

/// The kernel form: a stage's data are the control points' samples (k, P, u per point), the rows
/// the query's kernel rows ([`write_kernel_rows`]).
pub(crate) struct KernelForm {
    pub task_kernel: TaskKernel,
}

impl StageFields for KernelForm {
    #[inline(always)]
    fn task<S: Shape, const HESSIAN: bool>(&self, shape: S, samples: &[Real], k: &[Real]) -> (TaskField, TaskHessian) {
        kernel_task_field::<_, HESSIAN>(shape, &self.task_kernel, k, samples)
    }
    #[inline(always)]
    fn joint<S: Shape, const HESSIAN: bool>(&self, shape: S, samples: &[Real], rows: &[Real]) -> (JointField, JointHessian) {
        let (m, n) = (shape.m(), shape.n());
        joint_sums::<_, HESSIAN>(shape, samples, 2 * m + n, 2 * m, rows)
    }
}

/// The query state's right-hand side at one stage: the primal rates (eq. 20, the arithmetic of the
/// control points' flow) and, if `state` holds them, every direction's tangent rates.
///
/// `last`: the integration's last stage, whose δJ rates only move δJ(1), which nothing reads (the
/// exact Jacobian is δk(1), the transported one the primal J(1)): the fields' second derivatives
/// (task Hessian T, ∂_d Dv) are not computed and the δJ rates are written as zeros. Every other rate
/// is computed by the same arithmetic as on the other stages, so δk(1), k(1) and J(1) keep their bits.
/// A run-time flag (one branch per stage): the fields without second derivatives are those the
/// position-only evaluation inlines here anyway, so the last stage adds no copy of them.
#[inline(always)]
pub(crate) fn query_rates<S: Shape, F: StageFields>(
    shape: S,
    form: &F,
    stage: &[Real],
    rows: &[Real],
    state: &[Real],
    out: &mut [Real],
    last: bool,
) -> Option<()> {
    let (m, n) = (shape.m(), shape.n());
    let q = m + m * n;
    let (primal, tangents) = state.split_at_checked(q)?;
    let (out_primal, out_tangents) = out.split_at_mut_checked(q)?;
    let (k, jac) = unpack(shape, primal);
    let (dk, djac) = out_primal.split_at_mut_checked(m)?;
    let s_jac = primal.get(m..)?;
    if F::EXPLICIT {
        return explicit_rates(shape, form, stage, rows, &k, &jac, s_jac, tangents, dk, djac, out_tangents, last);
    }
    if tangents.is_empty() || last {
        let (tf, _) = form.task::<_, false>(shape, stage, &k);
        let (jf, _) = form.joint::<_, false>(shape, stage, rows);
        position_rates_shaped(shape, s_jac, &tf, &jf, dk, djac);
        let (mut tans, mut outs) = (tangents, out_tangents);
        for d in 0..n {
            let Some((tan, o)) = next_direction(shape, &mut tans, &mut outs) else { break };
            let (t_k, t_jac) = unpack(shape, tan);
            let (o_k, o_jac) = o.split_at_mut_checked(m)?;
            query_tangent_position_rate(shape, d, &jac, &tf, &jf, &t_k, &t_jac, o_k);
            o_jac.fill(0.0);
        }
        return Some(());
    }
    let (tf, t) = form.task::<_, true>(shape, stage, &k);
    let (jf, ddv) = form.joint::<_, true>(shape, stage, rows);
    position_rates_shaped(shape, s_jac, &tf, &jf, dk, djac);
    let (mut tans, mut outs) = (tangents, out_tangents);
    for (d, ddv_d) in ddv.iter().enumerate().take(n) {
        let Some((tan, o)) = next_direction(shape, &mut tans, &mut outs) else { break };
        let (t_k, t_jac) = unpack(shape, tan);
        let (o_k, o_jac) = o.split_at_mut_checked(m)?;
        query_tangent_position_rate(shape, d, &jac, &tf, &jf, &t_k, &t_jac, o_k);
        query_tangent_jacobian_rate(shape, &jac, &tf, &t, &jf, ddv_d, &t_k, &t_jac, o_jac);
    }
    Some(())
}

/// [`query_rates`] for a task field with an explicit ξ-dependence (the configuration term,
/// docs/DESIGN.md §16): the primal rates with w and Dw including the term, and each direction's
/// δk' = Dw δk − δJ v − J ∂_d v + ∂_d w. Only the last stage (its δJ rates zeros, as there): the
/// term's second derivatives are not computed, and the validated scheme, Euler × 1, has no other
/// stage (`None` for one, never a silently wrong δJ).
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn explicit_rates<S: Shape, F: StageFields>(
    shape: S,
    form: &F,
    stage: &[Real],
    rows: &[Real],
    k: &[Real; MT],
    jac: &[[Real; NJ]; MT],
    s_jac: &[Real],
    tangents: &[Real],
    dk: &mut [Real],
    djac: &mut [Real],
    out_tangents: &mut [Real],
    last: bool,
) -> Option<()> {
    if !last {
        return None;
    }
    let (tf, dxi) =
        if tangents.is_empty() { form.task_explicit::<_, false>(shape, stage, k) } else { form.task_explicit::<_, true>(shape, stage, k) };
    let (jf, _) = form.joint::<_, false>(shape, stage, rows);
    position_rates_shaped(shape, s_jac, &tf, &jf, dk, djac);
    let (m, n) = (shape.m(), shape.n());
    let (mut tans, mut outs) = (tangents, out_tangents);
    for d in 0..n {
        let Some((tan, o)) = next_direction(shape, &mut tans, &mut outs) else { break };
        let (t_k, t_jac) = unpack(shape, tan);
        let (o_k, o_jac) = o.split_at_mut_checked(m)?;
        query_tangent_position_rate(shape, d, jac, &tf, &jf, &t_k, &t_jac, o_k);
        // + ∂_d w
        for (o, dxi_a) in o_k.iter_mut().zip(dxi.iter()).take(m) {
            *o += dxi_a.get(d).copied().unwrap_or(0.0);
        }
        o_jac.fill(0.0);
    }
    Some(())
}

/// The next joint direction's tangent (δk_d, δJ_d, packed) from the front of `tans`, and its rates'
/// slot (δk_d', δJ_d') from the front of `outs`, both advanced past it; `None` when either runs
/// out. By splitting (a zip of two `chunks_exact` keeps a division-by-zero panic path). A step the
/// caller's loop takes (and unpacks in place), not a closure it hands over: the closure was compiled
/// out of line, with its tangents through memory (+12 % per evaluate on the M7 for the kernel form,
/// issue 52).
#[inline(always)]
fn next_direction<'t, 'o, S: Shape>(shape: S, tans: &mut &'t [Real], outs: &mut &'o mut [Real]) -> Option<(&'t [Real], &'o mut [Real])> {
    let q = shape.m() + shape.m() * shape.n();
    let (tan, t_rest) = tans.split_at_checked(q)?;
    let (o, o_rest) = core::mem::take(outs).split_at_mut_checked(q)?;
    (*tans, *outs) = (t_rest, o_rest);
    Some((tan, o))
}

/// Values of working space a query needs besides the kernel rows: its state with tangents and the
/// integrator's scratch.
pub const fn query_work_len(dims: Dims) -> usize {
    query_tangent_len(dims) + crate::integrate::scratch_len(query_tangent_len(dims))
}

#[cfg(test)]
mod tests;

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
//! scheme is the same scheme applied to the tangent system).

use crate::expansion::fields::ExpansionForm;
use crate::flow::{position_rates_shaped, task_field_sums, Dims, Fixed, JointField, Shape, TaskField, TaskHessian};
use crate::kernel::{joint_features, joint_kernel_parts_n, FEATURES_PER_JOINT};
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
/// D²k0_aug of [`crate::kinematics::effects_derivatives::hessian`]).
pub fn nominal_hessian(model: &NominalModel, x: &[f64]) -> NominalHessian {
    let mut h = [[[0.0; NJ]; NJ]; MT];
    write_nominal_hessian(model, x, &mut h);
    h
}

/// [`nominal_hessian`] written into `h`, which must hold zeros (no copy of the array on the way).
fn write_nominal_hessian(model: &NominalModel, x: &[f64], h: &mut NominalHessian) {
    if !model.effects().is_empty() {
        *h = crate::kinematics::effects_derivatives::hessian(model, x);
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
    if tangents.is_empty() || last {
        let (tf, _) = form.task::<_, false>(shape, stage, &k);
        let (jf, _) = form.joint::<_, false>(shape, stage, rows);
        position_rates_shaped(shape, s_jac, &tf, &jf, dk, djac);
        // Directions by splitting (a zip of two `chunks_exact` keeps a division-by-zero panic path).
        let (mut tans, mut outs) = (tangents, out_tangents);
        for d in 0..n {
            let (Some((tan, t_rest)), Some((o, o_rest))) = (tans.split_at_checked(q), core::mem::take(&mut outs).split_at_mut_checked(q))
            else {
                break;
            };
            (tans, outs) = (t_rest, o_rest);
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
        let (Some((tan, t_rest)), Some((o, o_rest))) = (tans.split_at_checked(q), core::mem::take(&mut outs).split_at_mut_checked(q))
        else {
            break;
        };
        (tans, outs) = (t_rest, o_rest);
        let (t_k, t_jac) = unpack(shape, tan);
        let (o_k, o_jac) = o.split_at_mut_checked(m)?;
        query_tangent_position_rate(shape, d, &jac, &tf, &jf, &t_k, &t_jac, o_k);
        query_tangent_jacobian_rate(shape, &jac, &tf, &t, &jf, ddv_d, &t_k, &t_jac, o_jac);
    }
    Some(())
}

/// The expansion's joint basis at ξ into `rows` and the support (out of line, like both integrations:
/// the kernel form's code stays as it was).
#[inline(never)]
#[allow(clippy::too_many_arguments)]
fn expansion_rows<S: Shape>(
    shape: S,
    kernel: &JointKernel,
    codes: &[u8],
    orders: &[u8; NJ],
    q: &[f64],
    fq: &[[Real; FEATURES_PER_JOINT]; NJ],
    features: &[Real],
    rows: &mut [Real],
    hessian: bool,
) -> f64 {
    crate::expansion::basis::write_joint_basis_shaped(shape, kernel, codes, orders, q, rows, hessian);
    crate::real::to_f64(crate::expansion::fields::support(shape, kernel, fq, features))
}

/// The query's integration with the expansion's stage fields (the kernel form's loop, with the
/// stage's weights c, d in place of its samples).
#[inline(never)]
#[allow(clippy::too_many_arguments)]
fn integrate_expansion<S: Shape>(
    shape: S,
    integrator: cbd_protocol::Integrator,
    task_kernel: TaskKernel,
    e: &cbd_protocol::FieldExpansion<'_>,
    task_orders: [u8; MT],
    weights: &[Real],
    rows: &[Real],
    y: &mut [Real],
    scratch: &mut [Real],
) -> Result<(), crate::Error> {
    let (m, n) = (shape.m(), shape.n());
    let stage_len = e.stage_len(n, m);
    let form = ExpansionForm { task_kernel, exponents: e.task_exponents, orders: task_orders, joint_len: e.n_joint_features as usize * n };
    let last = integrator.stage_count().saturating_sub(1);
    crate::integrate::integrate_checked(integrator.method, integrator.steps, y, scratch, crate::Error::Internal, |stage, s, out| {
        let w = weights.get(stage * stage_len..(stage + 1) * stage_len).ok_or(crate::Error::Internal)?;
        query_rates(shape, &form, w, rows, s, out, stage == last).ok_or(crate::Error::Internal)
    })
}

/// Values of working space a query needs besides the kernel rows: its state with tangents and the
/// integrator's scratch.
pub const fn query_work_len(dims: Dims) -> usize {
    query_tangent_len(dims) + crate::integrate::scratch_len(query_tangent_len(dims))
}

impl crate::Calibrator<'_> {
    /// eq. (20): the calibrated position k1(ξ) and the paper's transported J(1); with
    /// `exact_jacobian`, also the exact Jacobian Dk1(ξ) of the discrete flow (otherwise the
    /// Jacobian reported is J(1)). The position's arithmetic is the same either way.
    /// `EXACT_JACOBIAN` is a compile-time switch, not an argument: with both `evaluate` and
    /// `evaluate_transported` in one firmware (compensation calls both), a run-time flag kept
    /// the tangent branches inside the per-point loop and cost the M7 (dp) 6 % and the f32 build
    /// 27 % per `evaluate` (RR N = 256 Heun × 5; BENCHMARKS.md "Firmware (QEMU)").
    /// `tool_point` is j of [`cbd_protocol::NominalModel::tool_point`]: the query starts from k0_j(ξ),
    /// Dk0_j(ξ), D²k0_j(ξ) (the joint field v(ξ) and the task field are the same for every point).
    pub(crate) fn evaluate_query<const EXACT_JACOBIAN: bool>(
        &mut self,
        q: &[f64],
        tool_point: usize,
    ) -> Result<crate::Evaluation, crate::Error> {
        // The common shapes get loops unrolled at compile time; the arithmetic is the same.
        match (self.dims.m, self.dims.n) {
            (2, 2) => self.evaluate_shaped::<_, EXACT_JACOBIAN>(Fixed::<2, 2>, q, tool_point),
            (3, 6) => self.evaluate_shaped::<_, EXACT_JACOBIAN>(Fixed::<3, 6>, q, tool_point),
            _ => self.evaluate_shaped::<_, EXACT_JACOBIAN>(self.dims, q, tool_point),
        }
    }

    #[inline(always)]
    fn evaluate_shaped<S: Shape, const EXACT_JACOBIAN: bool>(
        &mut self,
        shape: S,
        q: &[f64],
        tool_point: usize,
    ) -> Result<crate::Evaluation, crate::Error> {
        let exact_jacobian = EXACT_JACOBIAN;
        use crate::Error;
        let dims = shape.dims();
        let (m, n) = (dims.m, dims.n);
        if q.len() != n {
            return Err(Error::QueryDimension { expected: n, found: q.len() });
        }
        if n == 0 || dims != self.dims {
            return Err(Error::Internal);
        }
        if let Some(index) = q.iter().position(|v| !v.is_finite()) {
            return Err(Error::NonFiniteQuery { index });
        }
        let count = self.model.nominal.tool_point_count();
        if tool_point >= count {
            return Err(Error::ToolPoint { index: tool_point, count });
        }
        let n_points = self.model.n_points as usize;
        // K_V(ξ, x_j) (or the joint basis at ξ), its gradient and Hessian do not change along the
        // flow: once per query. Working space: those rows, then the query state and the
        // integrator's scratch (in storage rather than on the stack: no zeroing of the largest
        // possible state per query).
        let n_rows = self.model.expansion.as_ref().map_or(n_points, |e| e.n_joint_features as usize);
        let (rows, rest) = self.work.split_at_mut_checked(n_rows * kernel_row_len(n)).ok_or(Error::Internal)?;
        let mut fq = [[0.0; FEATURES_PER_JOINT]; NJ];
        joint_features(&self.model.joint_kernel, q, &mut fq);
        // The rows' second derivatives feed only the δJ rates of the stages before the last
        // ([`query_rates`]): with one stage (Euler × 1) nothing reads them.
        let row_hessians = exact_jacobian && self.model.integrator.stage_count() > 1;
        let support = match &self.model.expansion {
            None => {
                let flow_kernel = self.model.joint_kernel.for_flow(self.model.momentum_law);
                crate::real::to_f64(write_kernel_rows(shape, &flow_kernel, &fq, self.features, rows, row_hessians))
                    / self.model.joint_kernel.gamma
            }
            Some(e) => expansion_rows(
                shape,
                &self.model.joint_kernel,
                e.joint_codes,
                &self.orders.joint,
                q,
                &fq,
                self.features,
                rows,
                row_hessians,
            ),
        };
        let rows: &[Real] = rows;
        let norm = &self.model.normalisation;
        let mut h0 = [[[0.0; NJ]; NJ]; MT];
        // k0_j, Dk0_j (and D²k0_j): the model itself for a model without tool points (no copy).
        let k0 = crate::kinematics::with_tool_point(&self.model.nominal, tool_point, |nominal| {
            if exact_jacobian {
                write_nominal_hessian(nominal, q, &mut h0);
            }
            crate::kinematics::forward_kinematics(nominal, q)
        })
        .ok_or(Error::Internal)?
        .normalised(norm);
        let ql = dims.query_len();
        let state_len = if exact_jacobian { query_tangent_len(dims) } else { ql };
        let (y, rest) = rest.split_at_mut_checked(state_len).ok_or(Error::Internal)?;
        let scratch = rest.get_mut(..crate::integrate::scratch_len(state_len)).ok_or(Error::Internal)?;
        // Every value is written before it is read; cleared anyway so that nothing of the previous
        // query can leak into this one.
        y.fill(0.0);
        scratch.fill(0.0);
        let inv_scale = 1.0 / norm.task_scale;
        {
            let (primal, tangents) = y.split_at_mut_checked(ql).ok_or(Error::Internal)?;
            let (y_k, y_jac) = primal.split_at_mut_checked(m).ok_or(Error::Internal)?;
            for (dst, src) in y_k.iter_mut().zip(k0.position.iter()) {
                *dst = *src as Real;
            }
            for (dst, src) in y_jac.chunks_exact_mut(n.max(1)).zip(k0.jacobian.iter()) {
                for (d, s) in dst.iter_mut().zip(src.iter()) {
                    *d = *s as Real;
                }
            }
            // δk_d(0) = ∂_d k0, δJ_d(0)[a][e] = ∂_e ∂_d k0_a (internal units).
            for (d, t) in tangents.chunks_exact_mut(ql.max(1)).enumerate() {
                let (t_k, t_jac) = t.split_at_mut_checked(m).ok_or(Error::Internal)?;
                for (dst, row) in t_k.iter_mut().zip(k0.jacobian.iter()) {
                    *dst = row.get(d).copied().unwrap_or(0.0) as Real;
                }
                for (dst_row, h_a) in t_jac.chunks_exact_mut(n.max(1)).zip(h0.iter()) {
                    for (dst, h_ae) in dst_row.iter_mut().zip(h_a.iter()) {
                        *dst = (h_ae.get(d).copied().unwrap_or(0.0) * inv_scale) as Real;
                    }
                }
            }
        }
        let integrator = self.model.integrator;
        let task_kernel = self.model.task_kernel;
        // One integration per form, each with its stage data resolved in its closure.
        match &self.model.expansion {
            None => {
                let (trajectory, block): (&[Real], usize) = (self.trajectory, n_points * dims.sample_len());
                let form = KernelForm { task_kernel };
                let last = integrator.stage_count().saturating_sub(1);
                crate::integrate::integrate_checked(integrator.method, integrator.steps, y, scratch, Error::Internal, |stage, s, out| {
                    let samples = trajectory.get(stage * block..(stage + 1) * block).ok_or(Error::Internal)?;
                    query_rates(shape, &form, samples, rows, s, out, stage == last).ok_or(Error::Internal)
                })?;
            }
            Some(e) => integrate_expansion(shape, integrator, task_kernel, e, self.orders.task, self.weights, rows, y, scratch)?,
        }
        let mut out = crate::Evaluation {
            position: nalgebra::SMatrix::zeros(),
            jacobian: nalgebra::SMatrix::zeros(),
            transported_jacobian: nalgebra::SMatrix::zeros(),
            task_dim: m,
            n_joints: n,
            support,
        };
        let (primal, tangents) = y.split_at_checked(ql).ok_or(Error::Internal)?;
        let (y_k, y_jac) = primal.split_at_checked(m).ok_or(Error::Internal)?;
        for ((dst, offset), v) in out.position.iter_mut().zip(norm.task_offset.iter()).zip(y_k) {
            *dst = offset + norm.task_scale * crate::real::to_f64(*v);
        }
        for (a, y_row) in y_jac.chunks_exact(n.max(1)).enumerate() {
            for (d, v) in y_row.iter().enumerate() {
                if let Some(dst) = out.transported_jacobian.get_mut((a, d)) {
                    *dst = norm.task_scale * crate::real::to_f64(*v);
                }
            }
        }
        if exact_jacobian {
            for (d, t) in tangents.chunks_exact(ql.max(1)).enumerate() {
                for (a, v) in t.iter().take(m).enumerate() {
                    if let Some(dst) = out.jacobian.get_mut((a, d)) {
                        *dst = norm.task_scale * crate::real::to_f64(*v);
                    }
                }
            }
        } else {
            out.jacobian = out.transported_jacobian;
        }
        // Over the matrices' storage (slices: nalgebra's strided iterators cost 20 instructions a value).
        let finite =
            out.position.as_slice().iter().chain(out.jacobian.as_slice()).chain(out.transported_jacobian.as_slice()).all(|v| v.is_finite());
        if finite {
            Ok(out)
        } else {
            Err(Error::NonFiniteResult)
        }
    }
}

#[cfg(test)]
mod tests;

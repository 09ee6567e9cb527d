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

use crate::flow::{Dims, JointField, TaskField};
use crate::kernel::task_kernel;
use cbd_protocol::{DhChain, JointKernel, JointKernelAxis, JointKind, NominalModel, TaskKernel, MAX_JOINTS as NJ, MAX_TASK_DIM as MT};

/// Second derivatives of the nominal model: `h[a][e][d] = ∂²k0_a / ∂x_e ∂x_d`, model units.
pub type NominalHessian = [[[f64; NJ]; NJ]; MT];

/// ∂²K_V(x, x')/∂x_b ∂x_d = K (f'_b f'_d + δ_bd f''_b), given K = `value`.
pub fn joint_kernel_hessian(kernel: &JointKernel, value: f64, x: &[f64], xp: &[f64], hess: &mut [[f64; NJ]; NJ]) {
    let mut first = [0.0; NJ];
    let mut second = [0.0; NJ];
    for (((axis, (a, b)), f1), f2) in kernel.axes.iter().zip(x.iter().zip(xp.iter())).zip(first.iter_mut()).zip(second.iter_mut()) {
        let delta = a - b;
        match *axis {
            JointKernelAxis::Periodic { b } => {
                *f1 = -b * libm::sin(delta);
                *f2 = -b * libm::cos(delta);
            }
            JointKernelAxis::Gaussian { width } => {
                let s = 1.0 / (width * width);
                *f1 = -delta * s;
                *f2 = -s;
            }
        }
    }
    let n = kernel.axes.len();
    for (b, ((row, f1b), f2b)) in hess.iter_mut().zip(first.iter()).zip(second.iter()).enumerate().take(n) {
        for (d, (h, f1d)) in row.iter_mut().zip(first.iter()).enumerate().take(n) {
            *h = value * (f1b * f1d + if b == d { *f2b } else { 0.0 });
        }
    }
}

/// Σ_j P_j[a] ∂²K_W(k, k_j)/∂k_c ∂k_b over one stage's samples: `t[a][c][b]`.
pub fn task_field_hessian(dims: Dims, kernel: &TaskKernel, k: &[f64], samples: &[f64]) -> [[[f64; MT]; MT]; MT] {
    let m = dims.m;
    let mut t = [[[0.0; MT]; MT]; MT];
    let inv_a2 = 1.0 / (kernel.width * kernel.width);
    let mut diff = [0.0; MT];
    let mut grad = [0.0; MT];
    let sample_len = dims.sample_len();
    if sample_len == 0 {
        return t;
    }
    for s in samples.chunks_exact(sample_len) {
        for ((d, ki), sj) in diff.iter_mut().zip(k.iter()).zip(s.iter()).take(m) {
            *d = ki - sj;
        }
        let kw = task_kernel(kernel, &diff, m, &mut grad);
        let p = s.get(m..2 * m).unwrap_or(&[]);
        for (t_a, p_a) in t.iter_mut().zip(p.iter()) {
            for (c, (t_ac, e_c)) in t_a.iter_mut().zip(diff.iter()).enumerate().take(m) {
                for (b, (t_acb, e_b)) in t_ac.iter_mut().zip(diff.iter()).enumerate().take(m) {
                    let h = kw * (e_c * e_b * inv_a2 * inv_a2 - if b == c { inv_a2 } else { 0.0 });
                    *t_acb += p_a * h;
                }
            }
        }
    }
    t
}

/// Second derivatives of the nominal forward kinematics at `x`.
pub fn nominal_hessian(model: &NominalModel, x: &[f64]) -> NominalHessian {
    let mut h = [[[0.0; NJ]; NJ]; MT];
    match model {
        // ∂²y/∂x_e∂x_d = Σ_{k ≥ max(d, e)} −l_k (cos θ_k, sin θ_k)
        NominalModel::PlanarChain { lengths, .. } => {
            let mut theta = 0.0;
            for (k, (l, xk)) in lengths.iter().zip(x).enumerate() {
                theta += xk;
                let term = [-l * libm::cos(theta), -l * libm::sin(theta)];
                for (h_a, t) in h.iter_mut().zip(term.iter()) {
                    for row in h_a.iter_mut().take(k + 1) {
                        for v in row.iter_mut().take(k + 1) {
                            *v += t;
                        }
                    }
                }
            }
        }
        NominalModel::DhChain(chain) => dh_hessian(chain, x, &mut h),
    }
    h
}

fn cross(a: &[f64; 3], b: &[f64; 3]) -> [f64; 3] {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}

fn sub(a: &[f64; 3], b: &[f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

// Column j of Dk0 is z_j × (p − o_j) (revolute) or z_j (prismatic). Its derivative with respect
// to joint i: the axes and origins of joints after i turn with joint i, and p moves with every joint.
fn dh_hessian(chain: &DhChain, x: &[f64], h: &mut NominalHessian) {
    let (axes, origins, p) = crate::nominal::dh_frames(chain, x);
    let n = chain.joints.len().min(x.len());
    for (j, (joint_j, (z_j, o_j))) in chain.joints.iter().zip(axes.iter().zip(origins.iter())).enumerate().take(n) {
        for (i, (joint_i, (z_i, o_i))) in chain.joints.iter().zip(axes.iter().zip(origins.iter())).enumerate().take(n) {
            let value = match (joint_j.kind, joint_i.kind) {
                // i ≤ j: z_j and (p − o_j) both rotate about z_i; i > j: only p moves.
                (JointKind::Revolute, JointKind::Revolute) if i <= j => cross(z_i, &cross(z_j, &sub(&p, o_j))),
                (JointKind::Revolute, JointKind::Revolute) => cross(z_j, &cross(z_i, &sub(&p, o_i))),
                // A prismatic joint before j translates p and o_j alike.
                (JointKind::Revolute, JointKind::Prismatic) if i < j => [0.0; 3],
                (JointKind::Revolute, JointKind::Prismatic) => cross(z_j, z_i),
                (JointKind::Prismatic, JointKind::Revolute) if i < j => cross(z_i, z_j),
                (JointKind::Prismatic, _) => [0.0; 3],
            };
            for (h_a, v) in h.iter_mut().zip(value.iter()) {
                if let Some(slot) = h_a.get_mut(i).and_then(|row| row.get_mut(j)) {
                    *slot = *v;
                }
            }
        }
    }
}

/// Per-stage quantities the tangent needs besides the primal fields.
pub struct SecondOrder {
    /// Σ_j P_j[a] ∂²K_W/∂k_c∂k_b, `[a][c][b]`.
    pub task: [[[f64; MT]; MT]; MT],
    /// ∂_d Dv(ξ)[f][e] = Σ_j u_j[f] ∂_e ∂_d K_V(ξ, x_j), `[d][f][e]`.
    pub joint: [[[f64; NJ]; NJ]; NJ],
}

/// ∂_d Dv at the query from the samples and the cached kernel rows ([`kernel_row_len`] per point;
/// the Hessian ∂_e ∂_d K_V sits after the value and gradient, at `1 + n + e·n + d`).
pub fn joint_field_hessian_from_rows(dims: Dims, samples: &[f64], kernel_rows: &[f64]) -> [[[f64; NJ]; NJ]; NJ] {
    let (m, n) = (dims.m, dims.n);
    let mut out = [[[0.0; NJ]; NJ]; NJ];
    let (sample_len, row_len) = (dims.sample_len(), kernel_row_len(n));
    if sample_len == 0 || n == 0 {
        return out;
    }
    for (s, row) in samples.chunks_exact(sample_len).zip(kernel_rows.chunks_exact(row_len)) {
        let u = s.get(2 * m..2 * m + n).unwrap_or(&[]);
        let hrow = row.get(1 + n..).unwrap_or(&[]);
        // hrow[e * n + d] = ∂_e ∂_d K_V
        for (d, out_d) in out.iter_mut().enumerate().take(n) {
            for (out_df, u_f) in out_d.iter_mut().zip(u.iter()) {
                for (e, o) in out_df.iter_mut().enumerate().take(n) {
                    *o += u_f * hrow.get(e * n + d).copied().unwrap_or(0.0);
                }
            }
        }
    }
    out
}

/// The rates of one direction's tangent (δk, δJ) given the stage's fields.
#[allow(clippy::too_many_arguments)]
pub fn tangent_rates(
    dims: Dims,
    direction: usize,
    jac: &[f64],
    tf: &TaskField,
    jf: &JointField,
    second: &SecondOrder,
    dk: &[f64],
    djac: &[f64],
    out_dk: &mut [f64],
    out_djac: &mut [f64],
) {
    let (m, n) = (dims.m, dims.n);
    fn row(mat: &[f64], a: usize, n: usize) -> &[f64] {
        mat.get(a * n..(a + 1) * n).unwrap_or(&[])
    }
    let ddv = second.joint.get(direction);
    // (D²w δk)[a][c] = Σ_b t[a][c][b] δk[b]
    let mut d2w = [[0.0; MT]; MT];
    for (d2w_a, t_a) in d2w.iter_mut().zip(second.task.iter()).take(m) {
        for (v, t_ac) in d2w_a.iter_mut().zip(t_a.iter()).take(m) {
            *v = t_ac.iter().zip(dk.iter()).map(|(t, d)| t * d).sum();
        }
    }
    for (a, (out_a, (dw_a, d2w_a))) in out_dk.iter_mut().zip(tf.dw.iter().zip(d2w.iter())).enumerate().take(m) {
        // δk' = Dw δk − δJ v − J Dv[:, d]
        let mut r: f64 = dw_a.iter().zip(dk.iter()).map(|(w, d)| w * d).sum();
        for ((dj, j), (v, dv_row)) in row(djac, a, n).iter().zip(row(jac, a, n)).zip(jf.v.iter().zip(jf.dv.iter())) {
            r -= dj * v + j * dv_row.get(direction).copied().unwrap_or(0.0);
        }
        *out_a = r;
        // δJ'[a][e] = Σ_c (D²w δk)[a][c] J[c][e] + Σ_c Dw[a][c] δJ[c][e] − Σ_f δJ[a][f] Dv[f][e] − Σ_f J[a][f] ∂_d Dv[f][e]
        let out_row = out_djac.get_mut(a * n..(a + 1) * n).unwrap_or(&mut []);
        for (e, o) in out_row.iter_mut().enumerate() {
            let mut r = 0.0;
            for (c, (d2, w)) in d2w_a.iter().zip(dw_a.iter()).enumerate().take(m) {
                let jce = row(jac, c, n).get(e).copied().unwrap_or(0.0);
                let djce = row(djac, c, n).get(e).copied().unwrap_or(0.0);
                r += d2 * jce + w * djce;
            }
            for (f, (djf, jf_)) in row(djac, a, n).iter().zip(row(jac, a, n)).enumerate() {
                let dv_fe = jf.dv.get(f).and_then(|r| r.get(e)).copied().unwrap_or(0.0);
                let ddv_fe = ddv.and_then(|m| m.get(f)).and_then(|r| r.get(e)).copied().unwrap_or(0.0);
                r -= djf * dv_fe + jf_ * ddv_fe;
            }
            *o = r;
        }
    }
}

/// Values per point of the query's kernel cache: K_V, its gradient (n) and Hessian (n × n).
pub const fn kernel_row_len(n: usize) -> usize {
    1 + n + n * n
}

/// Length of the query state with its tangents: (k, J) and one (δk, δJ) per joint.
pub const fn query_tangent_len(dims: Dims) -> usize {
    dims.query_len() * (1 + dims.n)
}

/// The combined query state's right-hand side at one stage: the primal rates (eq. 20, the same
/// arithmetic as the position-only evaluation) and every direction's tangent rates.
pub fn query_rates_with_tangents(
    dims: Dims,
    task_kernel: &TaskKernel,
    samples: &[f64],
    kernel_rows: &[f64],
    state: &[f64],
    out: &mut [f64],
) -> Option<()> {
    let (m, n, q) = (dims.m, dims.n, dims.query_len());
    let row_len = kernel_row_len(n);
    let (primal, tangents) = state.split_at_checked(q)?;
    let (out_primal, out_tangents) = out.split_at_mut_checked(q)?;
    let (s_k, s_jac) = primal.split_at_checked(m)?;
    let tf = crate::flow::task_field(dims, task_kernel, s_k, samples);
    let jf = crate::flow::joint_field(dims, samples, |j, g| {
        match kernel_rows.get(j * row_len..j * row_len + 1 + n).and_then(|r| r.split_first()) {
            Some((k, r_grad)) => {
                for (dst, src) in g.iter_mut().zip(r_grad) {
                    *dst = *src;
                }
                *k
            }
            None => {
                *g = [0.0; NJ];
                0.0
            }
        }
    });
    let (dk, djac) = out_primal.split_at_mut_checked(m)?;
    crate::flow::position_rates(dims, s_jac, &tf, &jf, dk, djac);
    if tangents.is_empty() {
        return Some(());
    }
    let joint = joint_field_hessian_from_rows(dims, samples, kernel_rows);
    let second = SecondOrder { task: task_field_hessian(dims, task_kernel, s_k, samples), joint };
    for (d, (t, o)) in tangents.chunks_exact(q).zip(out_tangents.chunks_exact_mut(q)).enumerate().take(n) {
        let (t_k, t_jac) = t.split_at_checked(m)?;
        let (o_k, o_jac) = o.split_at_mut_checked(m)?;
        tangent_rates(dims, d, s_jac, &tf, &jf, &second, t_k, t_jac, o_k, o_jac);
    }
    Some(())
}

/// Largest query state with tangents: (m + m·n)(1 + n).
const MAX_QUERY_TANGENT: usize = (MT + MT * NJ) * (1 + NJ);

impl crate::Calibrator<'_> {
    /// eq. (20): the calibrated position k1(ξ) and the paper's transported J(1); with
    /// `exact_jacobian`, also the exact Jacobian Dk1(ξ) of the discrete flow (otherwise the
    /// Jacobian reported is J(1)). The position's arithmetic is the same either way.
    pub(crate) fn evaluate_query(&mut self, q: &[f64], exact_jacobian: bool) -> Result<crate::Evaluation, crate::Error> {
        use crate::Error;
        let dims = self.dims;
        let (m, n) = (dims.m, dims.n);
        if q.len() != n {
            return Err(Error::QueryDimension { expected: n, found: q.len() });
        }
        if n == 0 {
            return Err(Error::Internal);
        }
        if let Some(index) = q.iter().position(|v| !v.is_finite()) {
            return Err(Error::NonFiniteQuery { index });
        }
        let n_points = self.model.n_points as usize;
        // K_V(ξ, x_j), its gradient and Hessian do not change along the flow: once per query.
        let row_len = kernel_row_len(n);
        let rows = self.work.get_mut(..n_points * row_len).ok_or(Error::Internal)?;
        let mut grad = [0.0; NJ];
        let mut hess = [[0.0; NJ]; NJ];
        let mut support: f64 = 0.0;
        for (j, r) in rows.chunks_exact_mut(row_len).enumerate() {
            let xj = self.points.get(j * n..(j + 1) * n).ok_or(Error::Internal)?;
            let k = crate::kernel::joint_kernel(&self.model.joint_kernel, q, xj, &mut grad);
            if exact_jacobian {
                joint_kernel_hessian(&self.model.joint_kernel, k, q, xj, &mut hess);
            }
            let (r_k, rest) = r.split_first_mut().ok_or(Error::Internal)?;
            let (r_grad, r_hess) = rest.split_at_mut_checked(n).ok_or(Error::Internal)?;
            *r_k = k;
            for (dst, g) in r_grad.iter_mut().zip(grad.iter()) {
                *dst = *g;
            }
            for (dst_row, h_row) in r_hess.chunks_exact_mut(n).zip(hess.iter()) {
                for (dst, h) in dst_row.iter_mut().zip(h_row.iter()) {
                    *dst = *h;
                }
            }
            support = support.max(k);
        }
        let rows: &[f64] = rows;
        let norm = &self.model.normalisation;
        let k0 = crate::nominal::forward_kinematics(&self.model.nominal, q).normalised(norm);
        let h0 = if exact_jacobian { nominal_hessian(&self.model.nominal, q) } else { [[[0.0; NJ]; NJ]; MT] };
        let ql = dims.query_len();
        let mut y = [0.0; MAX_QUERY_TANGENT];
        let state_len = if exact_jacobian { query_tangent_len(dims) } else { ql };
        let y = y.get_mut(..state_len).ok_or(Error::Internal)?;
        let inv_scale = 1.0 / norm.task_scale;
        {
            let (primal, tangents) = y.split_at_mut_checked(ql).ok_or(Error::Internal)?;
            let (y_k, y_jac) = primal.split_at_mut_checked(m).ok_or(Error::Internal)?;
            for (dst, src) in y_k.iter_mut().zip(k0.position.iter()) {
                *dst = *src;
            }
            for (dst, src) in y_jac.chunks_exact_mut(n).zip(k0.jacobian.iter()) {
                for (d, s) in dst.iter_mut().zip(src.iter()) {
                    *d = *s;
                }
            }
            // δk_d(0) = ∂_d k0, δJ_d(0)[a][e] = ∂_e ∂_d k0_a (internal units).
            for (d, t) in tangents.chunks_exact_mut(ql).enumerate() {
                let (t_k, t_jac) = t.split_at_mut_checked(m).ok_or(Error::Internal)?;
                for (dst, row) in t_k.iter_mut().zip(k0.jacobian.iter()) {
                    *dst = row.get(d).copied().unwrap_or(0.0);
                }
                for (dst_row, h_a) in t_jac.chunks_exact_mut(n).zip(h0.iter()) {
                    for (dst, h_ae) in dst_row.iter_mut().zip(h_a.iter()) {
                        *dst = h_ae.get(d).copied().unwrap_or(0.0) * inv_scale;
                    }
                }
            }
        }
        let mut scratch = [0.0; crate::integrate::scratch_len(MAX_QUERY_TANGENT)];
        let scratch = scratch.get_mut(..crate::integrate::scratch_len(y.len())).ok_or(Error::Internal)?;
        let block = n_points * dims.sample_len();
        let trajectory: &[f64] = self.trajectory;
        let task_kernel = self.model.task_kernel;
        crate::integrate::integrate(self.model.integrator.method, self.model.integrator.steps, y, scratch, |stage, s, out| {
            let samples = trajectory.get(stage * block..(stage + 1) * block).ok_or(Error::Internal)?;
            query_rates_with_tangents(dims, &task_kernel, samples, rows, s, out).ok_or(Error::Internal)
        })?;
        let mut out = crate::Evaluation {
            position: nalgebra::SMatrix::zeros(),
            jacobian: nalgebra::SMatrix::zeros(),
            transported_jacobian: nalgebra::SMatrix::zeros(),
            task_dim: m,
            n_joints: n,
            support: support / self.model.joint_kernel.gamma,
        };
        let (primal, tangents) = y.split_at_checked(ql).ok_or(Error::Internal)?;
        let (y_k, y_jac) = primal.split_at_checked(m).ok_or(Error::Internal)?;
        for ((dst, offset), v) in out.position.iter_mut().zip(norm.task_offset.iter()).zip(y_k) {
            *dst = offset + norm.task_scale * v;
        }
        for (a, y_row) in y_jac.chunks_exact(n).enumerate() {
            for (d, v) in y_row.iter().enumerate() {
                if let Some(dst) = out.transported_jacobian.get_mut((a, d)) {
                    *dst = norm.task_scale * v;
                }
            }
        }
        if exact_jacobian {
            for (d, t) in tangents.chunks_exact(ql).enumerate() {
                for (a, v) in t.iter().take(m).enumerate() {
                    if let Some(dst) = out.jacobian.get_mut((a, d)) {
                        *dst = norm.task_scale * v;
                    }
                }
            }
        } else {
            out.jacobian = out.transported_jacobian;
        }
        let finite = out.position.iter().chain(out.jacobian.iter()).chain(out.transported_jacobian.iter()).all(|v| v.is_finite());
        if finite {
            Ok(out)
        } else {
            Err(Error::NonFiniteResult)
        }
    }
}

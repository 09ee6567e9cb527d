//! The vector fields and the dynamics of DESIGN.md §2, for control points (eq. 17, 19) and
//! for a query configuration (eq. 20). One function computes each quantity; the trainer calls
//! the same functions, so trainer and runtime integrate bit-identical discrete flows.
//!
//! Layouts (row-major, all in internal units):
//! - control-point state, per point: `k (m) | J (m×n) | P (m)`, [`Dims::state_len`] values;
//! - trajectory sample, per point and stage: `k (m) | P (m) | u = Jᵀ P (n)`, [`Dims::sample_len`].

use crate::kernel::{joint_kernel, task_kernel};
use cbd_protocol::{JointKernel, MomentumLaw, TaskKernel, MAX_JOINTS, MAX_TASK_DIM};

/// Joint-space and task-space dimensions.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Dims {
    /// Joints, n.
    pub n: usize,
    /// Task-space dimension, m.
    pub m: usize,
}

impl Dims {
    /// Values per control point in the integrated state: k, J, P.
    pub const fn state_len(&self) -> usize {
        2 * self.m + self.m * self.n
    }
    /// Values per control point in a stored trajectory sample: k, P, u.
    pub const fn sample_len(&self) -> usize {
        2 * self.m + self.n
    }
    /// Values of the query state: k, J.
    pub const fn query_len(&self) -> usize {
        self.m + self.m * self.n
    }
}

/// w and its Jacobian Dw at a task-space point.
#[derive(Debug, Clone, Copy)]
pub struct TaskField {
    pub w: [f64; MAX_TASK_DIM],
    pub dw: [[f64; MAX_TASK_DIM]; MAX_TASK_DIM],
}

/// v and its Jacobian Dv (dv[a][b] = ∂v_a/∂x_b) at a joint configuration.
#[derive(Debug, Clone, Copy)]
pub struct JointField {
    pub v: [f64; MAX_JOINTS],
    pub dv: [[f64; MAX_JOINTS]; MAX_JOINTS],
}

/// Writes the trajectory sample (k_j, P_j, u_j = J_jᵀ P_j) of every control point.
pub fn write_samples(dims: Dims, state: &[f64], samples: &mut [f64]) {
    let (m, n) = (dims.m, dims.n);
    let (state_len, sample_len) = (dims.state_len(), dims.sample_len());
    if n == 0 || state_len == 0 || sample_len == 0 {
        return;
    }
    for (s, out) in state.chunks_exact(state_len).zip(samples.chunks_exact_mut(sample_len)) {
        let (Some((k, rest)), Some((out_k, out_rest))) = (s.split_at_checked(m), out.split_at_mut_checked(m)) else { return };
        let (Some((jac, p)), Some((out_p, out_u))) = (rest.split_at_checked(m * n), out_rest.split_at_mut_checked(m)) else { return };
        for (dst, src) in out_k.iter_mut().zip(k).chain(out_p.iter_mut().zip(p)) {
            *dst = *src;
        }
        // u_d = Σ_a J_ad P_a, summed over a in order for every d.
        for u in out_u.iter_mut() {
            *u = 0.0;
        }
        for (jac_a, p_a) in jac.chunks_exact(n).zip(p) {
            for (u, j) in out_u.iter_mut().zip(jac_a) {
                *u += j * p_a;
            }
        }
    }
}

/// w(k) = Σ_j K_W(k, k_j) P_j and Dw(k) = Σ_j P_j ∇K_W(k, k_j)ᵀ over one stage's samples.
pub fn task_field(dims: Dims, kernel: &TaskKernel, k: &[f64], samples: &[f64]) -> TaskField {
    let m = dims.m;
    let mut f = TaskField { w: [0.0; MAX_TASK_DIM], dw: [[0.0; MAX_TASK_DIM]; MAX_TASK_DIM] };
    let mut diff = [0.0; MAX_TASK_DIM];
    let mut grad = [0.0; MAX_TASK_DIM];
    let sample_len = dims.sample_len();
    if sample_len == 0 {
        return f;
    }
    for s in samples.chunks_exact(sample_len) {
        let Some((s_k, rest)) = s.split_at_checked(m) else { break };
        let Some((p, _)) = rest.split_at_checked(m) else { break };
        for ((e, k_c), s_c) in diff.iter_mut().zip(k).zip(s_k) {
            *e = k_c - s_c;
        }
        let kw = task_kernel(kernel, &diff, m, &mut grad);
        for ((w_a, dw_a), p_a) in f.w.iter_mut().zip(f.dw.iter_mut()).zip(p) {
            *w_a += kw * p_a;
            for (dw_ab, g_b) in dw_a.iter_mut().zip(grad.iter()).take(m) {
                *dw_ab += p_a * g_b;
            }
        }
    }
    f
}

/// v(x) = Σ_j K_V(x, x_j) u_j and Dv(x) = Σ_j u_j ∇_x K_V(x, x_j)ᵀ, with the kernel row supplied
/// by `kv(j, grad)` (computed on the fly for control points, cached for a query).
pub fn joint_field(dims: Dims, samples: &[f64], mut kv: impl FnMut(usize, &mut [f64; MAX_JOINTS]) -> f64) -> JointField {
    let (m, n) = (dims.m, dims.n);
    let mut f = JointField { v: [0.0; MAX_JOINTS], dv: [[0.0; MAX_JOINTS]; MAX_JOINTS] };
    let mut grad = [0.0; MAX_JOINTS];
    let sample_len = dims.sample_len();
    if sample_len == 0 {
        return f;
    }
    for (j, s) in samples.chunks_exact(sample_len).enumerate() {
        let k = kv(j, &mut grad);
        let Some(u) = s.get(2 * m..) else { break };
        for ((v_a, dv_a), u_a) in f.v.iter_mut().zip(f.dv.iter_mut()).zip(u) {
            *v_a += k * u_a;
            for (dv_ab, g_b) in dv_a.iter_mut().zip(grad.iter()).take(n) {
                *dv_ab += u_a * g_b;
            }
        }
    }
    f
}

/// eq. (17), (19), (20): dk = w(k) − J v(x), dJ = Dw(k) J − J Dv(x).
/// `jac` and `djac` are row-major m×n.
pub fn position_rates(dims: Dims, jac: &[f64], tf: &TaskField, jf: &JointField, dk: &mut [f64], djac: &mut [f64]) {
    let n = dims.n;
    if n == 0 {
        return;
    }
    // Row a of dJ: for every d, first + Σ_c Dw_ac J_cd (c in order), then − Σ_e J_ae Dv_ed (e in order).
    let rows = dk.iter_mut().zip(djac.chunks_exact_mut(n)).zip(jac.chunks_exact(n)).zip(tf.w.iter().zip(tf.dw.iter()));
    for (((dk_a, djac_a), jac_a), (w_a, dw_a)) in rows {
        let mut r = *w_a;
        for (j, v) in jac_a.iter().zip(jf.v.iter()) {
            r -= j * v;
        }
        *dk_a = r;
        for r in djac_a.iter_mut() {
            *r = 0.0;
        }
        for (dw_ac, jac_c) in dw_a.iter().zip(jac.chunks_exact(n)) {
            for (r, j) in djac_a.iter_mut().zip(jac_c) {
                *r += dw_ac * j;
            }
        }
        for (jac_ae, dv_e) in jac_a.iter().zip(jf.dv.iter()) {
            for (r, dv) in djac_a.iter_mut().zip(dv_e.iter()) {
                *r -= jac_ae * dv;
            }
        }
    }
}

/// (div v)(x) = trace Dv(x).
pub fn divergence(dims: Dims, jf: &JointField) -> f64 {
    let mut div = 0.0;
    for (d, dv_d) in jf.dv.iter().enumerate().take(dims.n) {
        if let Some(v) = dv_d.get(d) {
            div += v;
        }
    }
    div
}

/// Momentum law: dP = −Dw(k)ᵀ P − (div v)(x) P, or without the divergence term.
pub fn momentum_rate(dims: Dims, law: MomentumLaw, p: &[f64], tf: &TaskField, jf: &JointField, dp: &mut [f64]) {
    let m = dims.m;
    let div = match law {
        MomentumLaw::WithDivergence => divergence(dims, jf),
        MomentumLaw::WithoutDivergence => 0.0,
    };
    // For every a: − Σ_c Dw_ca P_c (c in order), then − div P_a.
    for r in dp.iter_mut().take(m) {
        *r = 0.0;
    }
    for (dw_c, p_c) in tf.dw.iter().zip(p).take(m) {
        for (r, dw) in dp.iter_mut().take(m).zip(dw_c.iter()) {
            *r -= dw * p_c;
        }
    }
    for (r, p_a) in dp.iter_mut().take(m).zip(p) {
        *r -= div * p_a;
    }
}

/// Everything the control-point dynamics need besides the state.
#[derive(Debug, Clone, Copy)]
pub struct FlowParams<'m> {
    pub dims: Dims,
    pub joint_kernel: &'m JointKernel,
    pub task_kernel: &'m TaskKernel,
    pub law: MomentumLaw,
}

/// eq. (17) + (19): the rates of control points `rows` (k, J, P), given the stage's samples of all
/// points and their configurations `points` (N × n). `out` holds the rates of `rows` only.
pub fn control_point_rates(
    params: &FlowParams<'_>,
    points: &[f64],
    state: &[f64],
    samples: &[f64],
    rows: core::ops::Range<usize>,
    out: &mut [f64],
) {
    let dims = params.dims;
    let (m, n, len) = (dims.m, dims.n, dims.state_len());
    if n == 0 || len == 0 {
        return;
    }
    let own = state.chunks_exact(len).zip(points.chunks_exact(n)).skip(rows.start).take(rows.len());
    for ((s, xi), rate) in own.zip(out.chunks_exact_mut(len)) {
        let Some((k, rest)) = s.split_at_checked(m) else { return };
        let Some((jac, p)) = rest.split_at_checked(m * n) else { return };
        let tf = task_field(dims, params.task_kernel, k, samples);
        let jf = joint_field(dims, samples, |j, g| match points.get(j * n..(j + 1) * n) {
            Some(xj) => joint_kernel(params.joint_kernel, xi, xj, g),
            None => {
                *g = [0.0; MAX_JOINTS];
                0.0
            }
        });
        let Some((dk, rest)) = rate.split_at_mut_checked(m) else { return };
        let Some((djac, dp)) = rest.split_at_mut_checked(m * n) else { return };
        position_rates(dims, jac, &tf, &jf, dk, djac);
        momentum_rate(dims, params.law, p, &tf, &jf, dp);
    }
}

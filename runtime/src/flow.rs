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
    for (s, out) in state.chunks_exact(dims.state_len()).zip(samples.chunks_exact_mut(dims.sample_len())) {
        let (k, rest) = s.split_at(m);
        let (jac, p) = rest.split_at(m * n);
        out[..m].copy_from_slice(k);
        out[m..2 * m].copy_from_slice(p);
        for d in 0..n {
            let mut u = 0.0;
            for a in 0..m {
                u += jac[a * n + d] * p[a];
            }
            out[2 * m + d] = u;
        }
    }
}

/// w(k) = Σ_j K_W(k, k_j) P_j and Dw(k) = Σ_j P_j ∇K_W(k, k_j)ᵀ over one stage's samples.
pub fn task_field(dims: Dims, kernel: &TaskKernel, k: &[f64], samples: &[f64]) -> TaskField {
    let m = dims.m;
    let mut f = TaskField { w: [0.0; MAX_TASK_DIM], dw: [[0.0; MAX_TASK_DIM]; MAX_TASK_DIM] };
    let mut diff = [0.0; MAX_TASK_DIM];
    let mut grad = [0.0; MAX_TASK_DIM];
    for s in samples.chunks_exact(dims.sample_len()) {
        for c in 0..m {
            diff[c] = k[c] - s[c];
        }
        let kw = task_kernel(kernel, &diff, m, &mut grad);
        let p = &s[m..2 * m];
        for a in 0..m {
            f.w[a] += kw * p[a];
            for b in 0..m {
                f.dw[a][b] += p[a] * grad[b];
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
    for (j, s) in samples.chunks_exact(dims.sample_len()).enumerate() {
        let k = kv(j, &mut grad);
        let u = &s[2 * m..2 * m + n];
        for a in 0..n {
            f.v[a] += k * u[a];
            for b in 0..n {
                f.dv[a][b] += u[a] * grad[b];
            }
        }
    }
    f
}

/// eq. (17), (19), (20): dk = w(k) − J v(x), dJ = Dw(k) J − J Dv(x).
/// `jac` and `djac` are row-major m×n.
pub fn position_rates(dims: Dims, jac: &[f64], tf: &TaskField, jf: &JointField, dk: &mut [f64], djac: &mut [f64]) {
    let (m, n) = (dims.m, dims.n);
    for a in 0..m {
        let mut r = tf.w[a];
        for d in 0..n {
            r -= jac[a * n + d] * jf.v[d];
        }
        dk[a] = r;
        for d in 0..n {
            let mut r = 0.0;
            for c in 0..m {
                r += tf.dw[a][c] * jac[c * n + d];
            }
            for e in 0..n {
                r -= jac[a * n + e] * jf.dv[e][d];
            }
            djac[a * n + d] = r;
        }
    }
}

/// (div v)(x) = trace Dv(x).
pub fn divergence(dims: Dims, jf: &JointField) -> f64 {
    let mut div = 0.0;
    for d in 0..dims.n {
        div += jf.dv[d][d];
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
    for a in 0..m {
        let mut r = 0.0;
        for c in 0..m {
            r -= tf.dw[c][a] * p[c];
        }
        dp[a] = r - div * p[a];
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
    for (i, rate) in rows.zip(out.chunks_exact_mut(len)) {
        let s = &state[i * len..(i + 1) * len];
        let xi = &points[i * n..(i + 1) * n];
        let tf = task_field(dims, params.task_kernel, &s[..m], samples);
        let jf = joint_field(dims, samples, |j, g| joint_kernel(params.joint_kernel, xi, &points[j * n..(j + 1) * n], g));
        let (dk, rest) = rate.split_at_mut(m);
        let (djac, dp) = rest.split_at_mut(m * n);
        position_rates(dims, &s[m..m + m * n], &tf, &jf, dk, djac);
        momentum_rate(dims, params.law, &s[m + m * n..], &tf, &jf, dp);
    }
}

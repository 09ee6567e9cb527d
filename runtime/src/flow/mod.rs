//! The vector fields and the dynamics of docs/DESIGN.md §2, for control points (eq. 17, 19) and
//! for a query configuration (eq. 20); beside them the control points' integration
//! (`control_points`), the query's derivatives (`query_derivatives`) and the inverse flows of
//! compensation's start (`inverse`). One function computes each quantity; the trainer calls the
//! same functions, so trainer and runtime integrate bit-identical discrete flows.
//!
//! Layouts (row-major, all in internal units):
//! - control-point state, per point: `k (m) | J (m×n) | P (m)`, [`Dims::state_len`] values;
//! - trajectory sample, per point and stage: `k (m) | P (m) | u = Jᵀ P (n)`, [`Dims::sample_len`].

pub mod configuration_field;
pub mod control_points;
pub mod inverse;
pub mod query_derivatives;
pub(crate) mod stage_fields;

use crate::kernel::{joint_features, joint_kernel_from_features, read_features, JointAxes, FEATURES_PER_JOINT};
use crate::real::{exp, Real};
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

/// The dimensions (m, n) as the hot loops see them: [`Dims`] at run time, or [`Fixed`] at compile
/// time, so that the loops of a common shape unroll. Both run the same arithmetic in the same
/// order, so results are bit-identical whichever is used.
pub trait Shape: Copy {
    /// Task-space dimension, m.
    fn m(self) -> usize;
    /// Joints, n.
    fn n(self) -> usize;
    /// The dimensions as run-time values.
    #[inline(always)]
    fn dims(self) -> Dims {
        Dims { n: self.n(), m: self.m() }
    }
}

impl Shape for Dims {
    #[inline(always)]
    fn m(self) -> usize {
        self.m
    }
    #[inline(always)]
    fn n(self) -> usize {
        self.n
    }
}

/// Task dimension `M` and joint count `N` known at compile time.
#[derive(Debug, Clone, Copy)]
pub struct Fixed<const M: usize, const N: usize>;

impl<const M: usize, const N: usize> Shape for Fixed<M, N> {
    #[inline(always)]
    fn m(self) -> usize {
        M
    }
    #[inline(always)]
    fn n(self) -> usize {
        N
    }
}

/// w and its Jacobian Dw at a task-space point.
#[derive(Debug, Clone, Copy)]
pub struct TaskField {
    /// w (internal units; the first m entries are used).
    pub w: [Real; MAX_TASK_DIM],
    /// Dw, `dw[a][b] = ∂w_a/∂y_b`.
    pub dw: [[Real; MAX_TASK_DIM]; MAX_TASK_DIM],
}

/// v and its Jacobian Dv (`dv[a][b] = ∂v_a/∂x_b`) at a joint configuration.
#[derive(Debug, Clone, Copy)]
pub struct JointField {
    /// v (joint units; the first n entries are used).
    pub v: [Real; MAX_JOINTS],
    /// Dv, `dv[a][b] = ∂v_a/∂x_b`.
    pub dv: [[Real; MAX_JOINTS]; MAX_JOINTS],
}

/// Writes the trajectory sample (k_j, P_j, u_j = J_jᵀ P_j) of every control point.
pub fn write_samples(dims: Dims, state: &[Real], samples: &mut [Real]) {
    let (m, n) = (dims.m, dims.n);
    let (state_len, sample_len) = (dims.state_len(), dims.sample_len());
    if n == 0 || state_len == 0 || sample_len == 0 {
        return;
    }
    for (s, out) in state.chunks_exact(state_len.max(1)).zip(samples.chunks_exact_mut(sample_len.max(1))) {
        let (Some((k, rest)), Some((out_k, out_rest))) = (s.split_at_checked(m), out.split_at_mut_checked(m)) else { return };
        let (Some((jac, p)), Some((out_p, out_u))) = (rest.split_at_checked(m * n), out_rest.split_at_mut_checked(m)) else { return };
        for (dst, src) in out_k.iter_mut().zip(k).chain(out_p.iter_mut().zip(p)) {
            *dst = *src;
        }
        // u_d = Σ_a J_ad P_a, summed over a in order for every d.
        for u in out_u.iter_mut() {
            *u = 0.0;
        }
        for (jac_a, p_a) in jac.chunks_exact(n.max(1)).zip(p) {
            for (u, j) in out_u.iter_mut().zip(jac_a) {
                *u += j * p_a;
            }
        }
    }
}

/// `Σ_j P_j[a] ∂²K_W(k, k_j)/∂k_c ∂k_b`, indexed `[a][c][b]` (the exact Jacobian's second-order term).
pub type TaskHessian = [[[Real; MAX_TASK_DIM]; MAX_TASK_DIM]; MAX_TASK_DIM];

/// w(k) = Σ_j K_W(k, k_j) P_j and Dw(k) = Σ_j P_j ∇K_W(k, k_j)ᵀ over one stage's samples.
pub fn task_field(dims: Dims, kernel: &TaskKernel, k: &[Real], samples: &[Real]) -> TaskField {
    task_sums::<_, false>(dims, kernel, k, samples).0
}

/// [`task_field`] (bit-identical) with the loops shaped by `shape`.
#[inline(always)]
pub fn task_field_shaped<S: Shape>(shape: S, kernel: &TaskKernel, k: &[Real], samples: &[Real]) -> TaskField {
    task_sums::<_, false>(shape, kernel, k, samples).0
}

/// [`task_field_shaped`] and (HESSIAN) [`task_field_with_hessian`] as one generic call
/// (bit-identical to both; zeros for the Hessian without HESSIAN).
#[inline(always)]
pub fn task_field_sums<S: Shape, const HESSIAN: bool>(
    shape: S,
    kernel: &TaskKernel,
    k: &[Real],
    samples: &[Real],
) -> (TaskField, TaskHessian) {
    task_sums::<_, HESSIAN>(shape, kernel, k, samples)
}

/// [`task_field`] (bit-identical) and, in the same pass, Σ_j P_j ∂²K_W(k, k_j).
pub fn task_field_with_hessian<S: Shape>(shape: S, kernel: &TaskKernel, k: &[Real], samples: &[Real]) -> (TaskField, TaskHessian) {
    task_sums::<_, true>(shape, kernel, k, samples)
}

/// With e_j = k − k_j and K_j = exp(−|e_j|²/(2a²)): w = Σ K_j P_j, Dw[a][b] = −(1/a²) Σ K_j P_j[a] e_j[b],
/// and (HESSIAN) T[a][c][b] = (1/a⁴) Σ K_j P_j[a] e_j[c] e_j[b] − δ_cb w[a]/a². One exp per sample.
#[inline(always)]
fn task_sums<S: Shape, const HESSIAN: bool>(shape: S, kernel: &TaskKernel, k: &[Real], samples: &[Real]) -> (TaskField, TaskHessian) {
    let m = shape.m();
    let mut f = TaskField { w: [0.0; MAX_TASK_DIM], dw: [[0.0; MAX_TASK_DIM]; MAX_TASK_DIM] };
    let mut t = [[[0.0; MAX_TASK_DIM]; MAX_TASK_DIM]; MAX_TASK_DIM];
    let width = kernel.width as Real;
    let inv_a2 = 1.0 / (width * width);
    let exponent_scale = -0.5 * inv_a2;
    let sample_len = 2 * m + shape.n();
    let mut kk = [0.0; MAX_TASK_DIM];
    for (dst, src) in kk.iter_mut().zip(k).take(m) {
        *dst = *src;
    }
    if sample_len == 0 {
        return (f, t);
    }
    // f.dw accumulates Σ K P[a] e[b] and t Σ K P[a] e[c] e[b]; both are scaled after the loop.
    for s in samples.chunks_exact(sample_len.max(1)) {
        let mut e = [0.0; MAX_TASK_DIM];
        let mut kp = [0.0; MAX_TASK_DIM];
        let mut r2 = 0.0;
        for ((e_c, k_c), s_c) in e.iter_mut().zip(kk.iter()).zip(s).take(m) {
            *e_c = k_c - s_c;
            r2 += *e_c * *e_c;
        }
        let kw = exp(exponent_scale * r2);
        for (kp_a, p_a) in kp.iter_mut().zip(s.iter().skip(m)).take(m) {
            *kp_a = kw * p_a;
        }
        for ((w_a, dw_a), kp_a) in f.w.iter_mut().zip(f.dw.iter_mut()).zip(kp.iter()).take(m) {
            *w_a += kp_a;
            for (dw_ab, e_b) in dw_a.iter_mut().zip(e.iter()).take(m) {
                *dw_ab += kp_a * e_b;
            }
        }
        if HESSIAN {
            for (t_a, kp_a) in t.iter_mut().zip(kp.iter()).take(m) {
                for (t_ac, e_c) in t_a.iter_mut().zip(e.iter()).take(m) {
                    let kpe = kp_a * e_c;
                    for (t_acb, e_b) in t_ac.iter_mut().zip(e.iter()).take(m) {
                        *t_acb += kpe * e_b;
                    }
                }
            }
        }
    }
    for dw_a in f.dw.iter_mut().take(m) {
        for dw_ab in dw_a.iter_mut().take(m) {
            *dw_ab *= -inv_a2;
        }
    }
    if HESSIAN {
        let inv_a4 = inv_a2 * inv_a2;
        for (t_a, w_a) in t.iter_mut().zip(f.w.iter()).take(m) {
            for (c, t_ac) in t_a.iter_mut().enumerate().take(m) {
                for (b, t_acb) in t_ac.iter_mut().enumerate().take(m) {
                    *t_acb *= inv_a4;
                    if b == c {
                        *t_acb -= w_a * inv_a2;
                    }
                }
            }
        }
    }
    (f, t)
}

/// v(x) = Σ_j K_V(x, x_j) u_j and Dv(x) = Σ_j u_j ∇_x K_V(x, x_j)ᵀ, with the kernel row supplied
/// by `kv(j, grad)` (computed on the fly for control points, cached for a query).
pub fn joint_field(dims: Dims, samples: &[Real], mut kv: impl FnMut(usize, &mut [Real; MAX_JOINTS]) -> Real) -> JointField {
    let (m, n) = (dims.m, dims.n);
    let mut f = JointField { v: [0.0; MAX_JOINTS], dv: [[0.0; MAX_JOINTS]; MAX_JOINTS] };
    let mut grad = [0.0; MAX_JOINTS];
    let sample_len = dims.sample_len();
    if sample_len == 0 {
        return f;
    }
    for (j, s) in samples.chunks_exact(sample_len.max(1)).enumerate() {
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
pub fn position_rates(dims: Dims, jac: &[Real], tf: &TaskField, jf: &JointField, dk: &mut [Real], djac: &mut [Real]) {
    position_rates_shaped(dims, jac, tf, jf, dk, djac)
}

/// [`position_rates`] (bit-identical) with the loops shaped by `shape`.
#[inline(always)]
pub fn position_rates_shaped<S: Shape>(shape: S, jac: &[Real], tf: &TaskField, jf: &JointField, dk: &mut [Real], djac: &mut [Real]) {
    let (m, n) = (shape.m(), shape.n());
    if n == 0 {
        return;
    }
    // Row a of dJ: for every d, first + Σ_c Dw_ac J_cd (c in order), then − Σ_e J_ae Dv_ed (e in order).
    let rows = dk.iter_mut().zip(djac.chunks_exact_mut(n.max(1))).zip(jac.chunks_exact(n.max(1))).zip(tf.w.iter().zip(tf.dw.iter()));
    for (((dk_a, djac_a), jac_a), (w_a, dw_a)) in rows.take(m) {
        let mut r = *w_a;
        for (j, v) in jac_a.iter().zip(jf.v.iter()) {
            r -= j * v;
        }
        *dk_a = r;
        for r in djac_a.iter_mut() {
            *r = 0.0;
        }
        for (dw_ac, jac_c) in dw_a.iter().zip(jac.chunks_exact(n.max(1))) {
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
pub fn divergence(dims: Dims, jf: &JointField) -> Real {
    let mut div = 0.0;
    for (d, dv_d) in jf.dv.iter().enumerate().take(dims.n) {
        if let Some(v) = dv_d.get(d) {
            div += v;
        }
    }
    div
}

/// Momentum law: dP = −Dw(k)ᵀ P − (div v)(x) P, or without the divergence term.
pub fn momentum_rate(dims: Dims, law: MomentumLaw, p: &[Real], tf: &TaskField, jf: &JointField, dp: &mut [Real]) {
    let m = dims.m;
    let div = if law.has_divergence() { divergence(dims, jf) } else { 0.0 };
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
#[derive(Debug)]
pub struct FlowParams<'m, K: JointAxes + ?Sized = JointKernel> {
    /// n and m.
    pub dims: Dims,
    /// K_V as the flow uses it (γ carries the law's sign: [`JointKernel::for_flow`]); the blob's,
    /// or any [`JointAxes`] (a test's axis form).
    pub joint_kernel: &'m K,
    /// K_W.
    pub task_kernel: &'m TaskKernel,
    /// Whether the momenta carry the −(div v) P term.
    pub law: MomentumLaw,
}

impl<K: JointAxes + ?Sized> Clone for FlowParams<'_, K> {
    fn clone(&self) -> Self {
        *self
    }
}

impl<K: JointAxes + ?Sized> Copy for FlowParams<'_, K> {}

/// eq. (17) + (19): the rates of control points `rows` (k, J, P), given the stage's samples of all
/// points and their configurations `points` (N × n). `out` holds the rates of `rows` only.
pub fn control_point_rates<K: JointAxes + ?Sized>(
    params: &FlowParams<'_, K>,
    points: &[f64],
    state: &[Real],
    samples: &[Real],
    rows: core::ops::Range<usize>,
    out: &mut [Real],
) {
    let n = params.dims.n;
    let kernel = params.joint_kernel;
    let features_of = |x: &[f64]| {
        let mut f = [[0.0; FEATURES_PER_JOINT]; MAX_JOINTS];
        joint_features(kernel, x, &mut f);
        f
    };
    let own = points.chunks_exact(n.max(1)).skip(rows.start).take(rows.len()).map(features_of);
    point_rates(params, own, state, samples, rows, out, |j| points.get(j * n..(j + 1) * n).map(features_of).unwrap_or_default());
}

/// [`control_point_rates`] (bit-identical) with the configurations' kernel features precomputed
/// ([`crate::kernel::write_features`]): no transcendental per pair of points but one exp.
pub fn control_point_rates_with_features<K: JointAxes + ?Sized>(
    params: &FlowParams<'_, K>,
    features: &[Real],
    state: &[Real],
    samples: &[Real],
    rows: core::ops::Range<usize>,
    out: &mut [Real],
) {
    let n = params.dims.n;
    let own = features.chunks_exact((n * FEATURES_PER_JOINT).max(1)).skip(rows.start).take(rows.len()).map(|f| read_features(f, n, 0));
    point_rates(params, own, state, samples, rows, out, |j| read_features(features, n, j));
}

/// The rates of control points `rows`, given their own kernel features (`own`) and every
/// point's (`features_of(j)`).
fn point_rates<K: JointAxes + ?Sized>(
    params: &FlowParams<'_, K>,
    own: impl Iterator<Item = [[Real; FEATURES_PER_JOINT]; MAX_JOINTS]>,
    state: &[Real],
    samples: &[Real],
    rows: core::ops::Range<usize>,
    out: &mut [Real],
    features_of: impl Fn(usize) -> [[Real; FEATURES_PER_JOINT]; MAX_JOINTS],
) {
    let dims = params.dims;
    let (m, n, len) = (dims.m, dims.n, dims.state_len());
    if n == 0 || len == 0 {
        return;
    }
    let own = state.chunks_exact(len.max(1)).skip(rows.start).take(rows.len()).zip(own);
    for ((s, fxi), rate) in own.zip(out.chunks_exact_mut(len.max(1))) {
        let Some((k, rest)) = s.split_at_checked(m) else { return };
        let Some((jac, p)) = rest.split_at_checked(m * n) else { return };
        let tf = task_field(dims, params.task_kernel, k, samples);
        let jf = joint_field(dims, samples, |j, g| joint_kernel_from_features(params.joint_kernel, &fxi, &features_of(j), g));
        let Some((dk, rest)) = rate.split_at_mut_checked(m) else { return };
        let Some((djac, dp)) = rest.split_at_mut_checked(m * n) else { return };
        position_rates(dims, jac, &tf, &jf, dk, djac);
        momentum_rate(dims, params.law, p, &tf, &jf, dp);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kernel::write_features;
    use cbd_protocol::JointKernelAxis;

    /// Samples of `count` points for dims (m, n): k, P, u from a fixed pseudo-random sequence.
    fn samples(dims: Dims, count: usize) -> ([Real; 64 * 8], usize) {
        let mut out = [0.0; 64 * 8];
        let len = count * dims.sample_len();
        let mut s = 0x1234_5678u32;
        for v in out.iter_mut().take(len) {
            s = s.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            *v = ((s >> 8) as f64 / 16_777_216.0 - 0.5) as Real;
        }
        (out, len)
    }

    #[test]
    #[allow(clippy::needless_range_loop)]
    #[cfg_attr(
        feature = "f32",
        ignore = "central differences at h = 1e-6 and 1e-8 tolerances are f64's (the f32 build's accuracy: the firmware's f32 rows)"
    )]
    fn task_field_hessian_matches_finite_differences_of_dw() {
        let dims = Dims { n: 2, m: 3 };
        let (s, len) = samples(dims, 9);
        let kernel = TaskKernel { width: 0.7 };
        let k: [Real; 3] = [0.1, -0.2, 0.15];
        let (tf, t) = task_field_with_hessian(dims, &kernel, &k, &s[..len]);
        let plain = task_field(dims, &kernel, &k, &s[..len]);
        // Same pass, same arithmetic: bit-identical to the plain field.
        assert_eq!(tf.w.map(Real::to_bits), plain.w.map(Real::to_bits));
        assert_eq!(tf.dw.map(|r| r.map(Real::to_bits)), plain.dw.map(|r| r.map(Real::to_bits)));
        let h: Real = 1e-6;
        for b in 0..3 {
            let (mut kp, mut km) = (k, k);
            kp[b] += h;
            km[b] -= h;
            let (fp, fm) = (task_field(dims, &kernel, &kp, &s[..len]), task_field(dims, &kernel, &km, &s[..len]));
            for a in 0..3 {
                // Dw[a][b] against differences of w, and T[a][c][b] against differences of Dw[a][c].
                let fd_w = (fp.w[a] - fm.w[a]) / (2.0 * h);
                assert!((fd_w - tf.dw[a][b]).abs() < 1e-8, "Dw[{a}][{b}]: {fd_w} vs {}", tf.dw[a][b]);
                for c in 0..3 {
                    let fd = (fp.dw[a][c] - fm.dw[a][c]) / (2.0 * h);
                    assert!((fd - t[a][c][b]).abs() < 1e-7, "T[{a}][{c}][{b}]: {fd} vs {}", t[a][c][b]);
                }
            }
        }
    }

    #[test]
    fn shaped_and_run_time_dimensions_give_identical_bits() {
        let dims = Dims { n: 2, m: 2 };
        let (s, len) = samples(dims, 16);
        let kernel = TaskKernel { width: 1.3 };
        let k: [Real; 2] = [0.05, 0.2];
        let (a, ta) = task_field_with_hessian(dims, &kernel, &k, &s[..len]);
        let (b, tb) = task_field_with_hessian(Fixed::<2, 2>, &kernel, &k, &s[..len]);
        assert_eq!(a.w.map(Real::to_bits), b.w.map(Real::to_bits));
        assert_eq!(a.dw.map(|r| r.map(Real::to_bits)), b.dw.map(|r| r.map(Real::to_bits)));
        assert_eq!(ta.map(|r| r.map(|c| c.map(Real::to_bits))), tb.map(|r| r.map(|c| c.map(Real::to_bits))));
    }

    #[test]
    fn control_point_rates_from_features_are_bit_identical() {
        let dims = Dims { n: 2, m: 2 };
        let count = 6;
        let joint_kernel = JointKernel {
            gamma: 2.0,
            axes: heapless::Vec::from_slice(&[JointKernelAxis::Periodic { b: 1.1 }, JointKernelAxis::Gaussian { width: 0.8 }]).unwrap(),
        };
        let params =
            FlowParams { dims, joint_kernel: &joint_kernel, task_kernel: &TaskKernel { width: 0.9 }, law: MomentumLaw::WithDivergence };
        let points: [f64; 12] = [0.1, -2.0, 1.5, 0.3, -0.7, 2.9, 3.0, -1.1, 0.0, 0.4, -2.5, 1.0];
        let mut features: [Real; 24] = [0.0; 24];
        write_features(&joint_kernel, 2, &points, &mut features);
        let (state, _) = samples(Dims { n: 8, m: 0 }, count); // any values: 8 = state_len for (2, 2)
        let mut smp: [Real; 36] = [0.0; 36];
        write_samples(dims, &state[..48], &mut smp);
        let (mut a, mut b): ([Real; 48], [Real; 48]) = ([0.0; 48], [0.0; 48]);
        control_point_rates(&params, &points, &state[..48], &smp, 0..count, &mut a);
        control_point_rates_with_features(&params, &features, &state[..48], &smp, 0..count, &mut b);
        assert_eq!(a.map(Real::to_bits), b.map(Real::to_bits));
        assert!(a.iter().any(|v| *v != 0.0));
    }
}

//! The configuration-dependent task field (format 8, docs/DESIGN.md §16): at a query ξ the task
//! field becomes
//!
//! ```text
//! w(k; ξ) = Σ_j [K_W(k, k_j) + c_j(ξ) K_X(k, k_j)] P_j,   c_j(ξ) = γ_C exp(Σ_d f_d(ξ_d − q_jd))
//! ```
//!
//! K_X(y, y') = exp(−|y − y'|²/(2 a_C²)), or 1 without a task width (flat). ξ is fixed along the
//! flow (a flow on Q × X that keeps q fixed), so c_j and ∇c_j are computed once per query
//! ([`write_configuration_rows`]). The model is Euler × 1 (validated), whose only stage is the
//! initial state: the control points never move and only the query's field changes. The tangent
//! of direction d gains the explicit derivative ∂_d w = Σ_j ∂_d c_j K_X(k, k_j) P_j, and Dw gains
//! Σ_j c_j P_j ∇_k K_Xᵀ; the task Hessian (δJ's rate) is never read for Euler × 1 (its only stage
//! is the last, [`crate::flow::query_derivatives`]).

pub use crate::flow::stage_fields::ExplicitDerivative;
use crate::flow::stage_fields::{joint_sums, JointHessian, StageFields};
use crate::flow::{JointField, Shape, TaskField, TaskHessian};
use crate::kernel::{axes_kernel_parts_n, FEATURES_PER_JOINT};
use crate::real::{exp, Real};
use cbd_protocol::{ConfigurationKernel, TaskKernel, MAX_JOINTS as NJ, MAX_TASK_DIM as MT};

/// Values per control point of the query's configuration rows: c_j(ξ) and ∇_ξ c_j (n).
pub const fn configuration_row_len(n: usize) -> usize {
    1 + n
}

/// Writes c_j(ξ) = γ_C exp(Σ_d f_d(ξ_d − q_jd)) and ∂_d c_j = c_j f'_d per control point: `fq` the
/// query's kernel features, `features` the control points' (N × n × 2; the configuration kernel's
/// axes have the joint kernel's form, so one table serves both). One exp per control point.
pub fn write_configuration_rows<S: Shape>(
    shape: S,
    kernel: &ConfigurationKernel,
    fq: &[[Real; FEATURES_PER_JOINT]; NJ],
    features: &[Real],
    rows: &mut [Real],
) {
    let n = shape.n();
    if n == 0 {
        return;
    }
    let (mut pairs, _) = features.as_chunks::<FEATURES_PER_JOINT>();
    for r in rows.chunks_exact_mut(configuration_row_len(n).max(1)) {
        let Some((fxj, rest)) = pairs.split_at_checked(n) else { break };
        pairs = rest;
        let (mut first, mut second) = ([0.0; NJ], [0.0; NJ]);
        let c = axes_kernel_parts_n(kernel.gamma, &kernel.axes, n, fq, fxj, &mut first, &mut second);
        let Some((r_c, r_grad)) = r.split_first_mut() else { return };
        *r_c = c;
        for (dst, f1) in r_grad.iter_mut().zip(first.iter()) {
            *dst = c * f1;
        }
    }
}

/// With e_j = k − k_j, K_j = exp(−|e_j|²/(2a²)), X_j = K_X(k, k_j) and g_j = c_j X_j:
/// w = Σ (K_j + g_j) P_j, Dw[a][b] = −Σ (K_j/a² + g_j/a_C²) P_j[a] e_j[b] (no g_j term when flat),
/// and (EXPLICIT) ∂_ξ w[a][d] = Σ X_j P_j[a] ∂_d c_j. `samples` one stage's (k, P, u) per control
/// point, `rows` the [`write_configuration_rows`] of the query. Two exps per sample (one when flat).
pub fn configuration_task_field<S: Shape, const EXPLICIT: bool>(
    shape: S,
    kernel: &TaskKernel,
    task_width: Option<f64>,
    k: &[Real],
    samples: &[Real],
    rows: &[Real],
) -> (TaskField, ExplicitDerivative) {
    let (m, n) = (shape.m(), shape.n());
    let mut f = TaskField { w: [0.0; MT], dw: [[0.0; MT]; MT] };
    let mut dxi = [[0.0; NJ]; MT];
    let width = kernel.width as Real;
    let inv_a2 = 1.0 / (width * width);
    let exponent_scale = -0.5 * inv_a2;
    // K_X's 1/a_C² (0 when flat: X_j = 1, no k-dependence).
    let inv_c2 = task_width.map_or(0.0, |a| {
        let a = a as Real;
        1.0 / (a * a)
    });
    let c_exponent_scale = -0.5 * inv_c2;
    let flat = task_width.is_none();
    let sample_len = 2 * m + n;
    let mut kk = [0.0; MT];
    for (dst, src) in kk.iter_mut().zip(k).take(m) {
        *dst = *src;
    }
    if sample_len == 0 || n == 0 {
        return (f, dxi);
    }
    let mut row_iter = rows.chunks_exact(configuration_row_len(n).max(1));
    // f.dw accumulates Σ (K/a² + g/a_C²) P[a] e[b], negated after the loop.
    for s in samples.chunks_exact(sample_len.max(1)) {
        let Some(row) = row_iter.next() else { break };
        let Some((c, grad_c)) = row.split_first() else { break };
        let mut e = [0.0; MT];
        let mut r2 = 0.0;
        for ((e_c, k_c), s_c) in e.iter_mut().zip(kk.iter()).zip(s).take(m) {
            *e_c = k_c - s_c;
            r2 += *e_c * *e_c;
        }
        let kw = exp(exponent_scale * r2);
        let kx = if flat { 1.0 } else { exp(c_exponent_scale * r2) };
        let g = c * kx;
        let (total, slope) = (kw + g, kw * inv_a2 + g * inv_c2);
        for (((w_a, dw_a), dxi_a), p_a) in f.w.iter_mut().zip(f.dw.iter_mut()).zip(dxi.iter_mut()).zip(s.iter().skip(m)).take(m) {
            *w_a += total * p_a;
            let hp = slope * p_a;
            for (dw_ab, e_b) in dw_a.iter_mut().zip(e.iter()).take(m) {
                *dw_ab += hp * e_b;
            }
            if EXPLICIT {
                let xp = kx * p_a;
                for (o, g_d) in dxi_a.iter_mut().zip(grad_c.iter()).take(n) {
                    *o += xp * g_d;
                }
            }
        }
    }
    for dw_a in f.dw.iter_mut().take(m) {
        for dw_ab in dw_a.iter_mut().take(m) {
            *dw_ab = -*dw_ab;
        }
    }
    (f, dxi)
}

/// The kernel form with the configuration term: the control points' samples, the query's kernel
/// rows for v, and its configuration rows ([`write_configuration_rows`]) for the task field.
pub(crate) struct ConfigurationForm<'r> {
    pub task_kernel: TaskKernel,
    pub task_width: Option<f64>,
    pub rows: &'r [Real],
}

impl StageFields for ConfigurationForm<'_> {
    const EXPLICIT: bool = true;
    /// The field with the term, without second derivatives whatever HESSIAN: they are never read
    /// ([`crate::flow::query_derivatives`] refuses a stage before the last for an explicit form, and
    /// Euler × 1's only stage is the last).
    #[inline(always)]
    fn task<S: Shape, const HESSIAN: bool>(&self, shape: S, samples: &[Real], k: &[Real]) -> (TaskField, TaskHessian) {
        let (tf, _) = configuration_task_field::<_, false>(shape, &self.task_kernel, self.task_width, k, samples, self.rows);
        (tf, [[[0.0; MT]; MT]; MT])
    }
    #[inline(always)]
    fn joint<S: Shape, const HESSIAN: bool>(&self, shape: S, samples: &[Real], rows: &[Real]) -> (JointField, JointHessian) {
        let (m, n) = (shape.m(), shape.n());
        joint_sums::<_, HESSIAN>(shape, samples, 2 * m + n, 2 * m, rows)
    }
    #[inline(always)]
    fn task_explicit<S: Shape, const DERIVATIVE: bool>(&self, shape: S, samples: &[Real], k: &[Real]) -> (TaskField, ExplicitDerivative) {
        configuration_task_field::<_, DERIVATIVE>(shape, &self.task_kernel, self.task_width, k, samples, self.rows)
    }
}

#[cfg(all(test, not(feature = "f32")))]
mod tests {
    use super::*;
    use crate::flow::{task_field, Dims, Fixed};
    use crate::kernel::{axes_features, write_features};
    use cbd_protocol::{JointKernel, JointKernelAxis};
    use heapless::Vec as HVec;

    const N: usize = 7;
    const DIMS: Dims = Dims { n: 3, m: 3 };

    fn kernel(task_width: Option<f64>) -> ConfigurationKernel {
        let axes = [JointKernelAxis::Periodic { b: 1.2 }, JointKernelAxis::Gaussian { width: 0.8 }, JointKernelAxis::Periodic { b: 0.5 }];
        ConfigurationKernel { gamma: 0.6, axes: HVec::from_slice(&axes).unwrap(), task_width }
    }

    /// Samples (k, P, u) and configurations of N control points from a fixed sequence.
    fn data() -> ([f64; N * 9], [f64; N * 3]) {
        let mut s = 0x0c0f_fee5u32;
        let mut next = || {
            s = s.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (s >> 8) as f64 / 16_777_216.0 - 0.5
        };
        (core::array::from_fn(|_| next()), core::array::from_fn(|_| 4.0 * next()))
    }

    fn field(c: &ConfigurationKernel, xi: &[f64; 3], k: &[f64; 3], explicit: bool) -> (TaskField, ExplicitDerivative) {
        let (samples, points) = data();
        let mut features = [0.0; N * 3 * FEATURES_PER_JOINT];
        let joint = JointKernel { gamma: 1.0, axes: c.axes.clone() };
        write_features(&joint, 3, &points, &mut features);
        let mut fq = [[0.0; FEATURES_PER_JOINT]; NJ];
        axes_features(&c.axes, xi, &mut fq);
        let mut rows = [0.0; N * 4];
        write_configuration_rows(Fixed::<3, 3>, c, &fq, &features, &mut rows);
        let task = TaskKernel { width: 0.7 };
        if explicit {
            configuration_task_field::<_, true>(DIMS, &task, c.task_width, k, &samples, &rows)
        } else {
            configuration_task_field::<_, false>(DIMS, &task, c.task_width, k, &samples, &rows)
        }
    }

    #[test]
    fn dw_and_the_explicit_derivative_match_finite_differences() {
        let (xi, k) = ([0.4, -0.3, 2.0], [0.1, -0.2, 0.15]);
        let h = 1e-6;
        for width in [None, Some(0.9)] {
            let c = kernel(width);
            let (tf, dxi) = field(&c, &xi, &k, true);
            // Without the explicit derivative: the same field, bit for bit.
            let (plain, _) = field(&c, &xi, &k, false);
            assert_eq!(tf.w.map(f64::to_bits), plain.w.map(f64::to_bits));
            for b in 0..3 {
                let (mut kp, mut km, mut xp, mut xm) = (k, k, xi, xi);
                kp[b] += h;
                km[b] -= h;
                xp[b] += h;
                xm[b] -= h;
                let (fk_p, fk_m) = (field(&c, &xi, &kp, false).0, field(&c, &xi, &km, false).0);
                let (fx_p, fx_m) = (field(&c, &xp, &k, false).0, field(&c, &xm, &k, false).0);
                for a in 0..3 {
                    let fd = (fk_p.w[a] - fk_m.w[a]) / (2.0 * h);
                    assert!((fd - tf.dw[a][b]).abs() < 1e-8, "width {width:?} Dw[{a}][{b}]: {fd} vs {}", tf.dw[a][b]);
                    let fd = (fx_p.w[a] - fx_m.w[a]) / (2.0 * h);
                    assert!((fd - dxi[a][b]).abs() < 1e-8, "width {width:?} ∂_ξ w[{a}][{b}]: {fd} vs {}", dxi[a][b]);
                }
            }
        }
    }

    #[test]
    fn the_field_is_k_w_plus_the_direct_sum_of_the_term() {
        let (xi, k) = ([0.4, -0.3, 2.0], [0.1, -0.2, 0.15]);
        let (samples, points) = data();
        for width in [None, Some(0.9)] {
            let c = kernel(width);
            let (tf, _) = field(&c, &xi, &k, false);
            let plain = task_field(DIMS, &TaskKernel { width: 0.7 }, &k, &samples);
            for a in 0..3 {
                let mut term = 0.0;
                for j in 0..N {
                    let q = &points[j * 3..j * 3 + 3];
                    let cj = 0.6
                        * libm::exp(
                            1.2 * (libm::cos(xi[0] - q[0]) - 1.0) - (xi[1] - q[1]) * (xi[1] - q[1]) / (2.0 * 0.64)
                                + 0.5 * (libm::cos(xi[2] - q[2]) - 1.0),
                        );
                    let s = &samples[j * 9..j * 9 + 9];
                    let r2: f64 = (0..3).map(|i| (k[i] - s[i]) * (k[i] - s[i])).sum();
                    let kx = width.map_or(1.0, |w| libm::exp(-r2 / (2.0 * w * w)));
                    term += cj * kx * s[3 + a];
                }
                assert!((tf.w[a] - plain.w[a] - term).abs() < 1e-14, "width {width:?} w[{a}]: {} vs {}", tf.w[a] - plain.w[a], term);
            }
        }
    }
}

//! The two reproducing kernels: K_V on joint space, K_W on task space (docs/DESIGN.md §1). K_V's
//! per-axis forms are [`axis`]'s; the functions here are written once over any [`AxisKernel`].

pub mod axis;
pub(crate) mod hermite;

pub use axis::AxisKernel;

use crate::real::{exp, Real};
use cbd_protocol::{JointKernel, JointKernelAxis, TaskKernel, MAX_JOINTS, MAX_TASK_DIM};

/// A joint kernel K_V = γ exp(Σ_d f_d): its amplitude and its axes. The blob's [`JointKernel`]; the
/// kernel functions here and the flow (`crate::flow::FlowParams`) are written once over it.
pub trait JointAxes {
    /// The axes' form type.
    type Axis: AxisKernel;
    /// γ.
    fn gamma(&self) -> f64;
    /// f_d, one per joint.
    fn axes(&self) -> &[Self::Axis];
}

impl JointAxes for JointKernel {
    type Axis = JointKernelAxis;
    #[inline(always)]
    fn gamma(&self) -> f64 {
        self.gamma
    }
    #[inline(always)]
    fn axes(&self) -> &[JointKernelAxis] {
        &self.axes
    }
}

/// Values per joint of a configuration's kernel features ([`joint_features`]).
pub const FEATURES_PER_JOINT: usize = 2;

/// The per-joint quantities K_V needs from one configuration ([`AxisKernel::features`]: (cos x_d,
/// sin x_d) on periodic axes, (x_d, 0) on Gaussian axes). Computed once per configuration (for the
/// control points at load time), so that a kernel value costs one `exp` and no other transcendental.
#[inline]
pub fn joint_features<K: JointAxes + ?Sized>(kernel: &K, x: &[f64], out: &mut [[Real; FEATURES_PER_JOINT]; MAX_JOINTS]) {
    axes_features(kernel.axes(), x, out)
}

/// [`joint_features`] of any axes.
#[inline]
pub fn axes_features<A: AxisKernel>(axes: &[A], x: &[f64], out: &mut [[Real; FEATURES_PER_JOINT]; MAX_JOINTS]) {
    for (o, (axis, xd)) in out.iter_mut().zip(axes.iter().zip(x.iter())) {
        *o = axis.features(*xd);
    }
}

/// Values of the kernel-feature table of `n_points` configurations ([`write_features`]).
pub const fn features_len(n_points: usize, n_joints: usize) -> usize {
    n_points * n_joints * FEATURES_PER_JOINT
}

/// The [`joint_features`] of every configuration in `points` (N × n), N × n × 2 values.
pub fn write_features<K: JointAxes + ?Sized>(kernel: &K, n: usize, points: &[f64], features: &mut [Real]) {
    let mut f = [[0.0; FEATURES_PER_JOINT]; MAX_JOINTS];
    for (x, out) in points.chunks_exact(n.max(1)).zip(features.chunks_exact_mut((n * FEATURES_PER_JOINT).max(1))) {
        joint_features(kernel, x, &mut f);
        for (dst, src) in out.iter_mut().zip(f.iter().flatten()) {
            *dst = *src;
        }
    }
}

/// Reads configuration `j`'s features from a [`write_features`] table.
#[inline]
pub fn read_features(features: &[Real], n: usize, j: usize) -> [[Real; FEATURES_PER_JOINT]; MAX_JOINTS] {
    let mut f = [[0.0; FEATURES_PER_JOINT]; MAX_JOINTS];
    let len = n * FEATURES_PER_JOINT;
    if let Some(src) = features.get(j * len..(j + 1) * len) {
        for (dst, s) in f.iter_mut().zip(src.chunks_exact(FEATURES_PER_JOINT)) {
            if let &[c, s] = s {
                *dst = [c, s];
            }
        }
    }
    f
}

/// K_V(x, x') = γ exp(Σ_d f_d(x_d − x'_d)) from both configurations' [`joint_features`], with the
/// per-axis first and second derivatives f'_d, f''_d (with respect to x) in `first`, `second`.
/// f_d and its derivatives are the axis form's ([`AxisKernel::terms`]).
#[inline]
pub fn joint_kernel_parts<K: JointAxes + ?Sized>(
    kernel: &K,
    fx: &[[Real; FEATURES_PER_JOINT]],
    fxp: &[[Real; FEATURES_PER_JOINT]],
    first: &mut [Real; MAX_JOINTS],
    second: &mut [Real; MAX_JOINTS],
) -> Real {
    joint_kernel_parts_n(kernel, MAX_JOINTS, fx, fxp, first, second)
}

/// [`joint_kernel_parts`] (bit-identical) over at most `n` axes: with `n` a constant the loop unrolls.
#[inline(always)]
pub fn joint_kernel_parts_n<K: JointAxes + ?Sized>(
    kernel: &K,
    n: usize,
    fx: &[[Real; FEATURES_PER_JOINT]],
    fxp: &[[Real; FEATURES_PER_JOINT]],
    first: &mut [Real; MAX_JOINTS],
    second: &mut [Real; MAX_JOINTS],
) -> Real {
    axes_kernel_parts_n(kernel.gamma(), kernel.axes(), n, fx, fxp, first, second)
}

/// [`joint_kernel_parts_n`] of amplitude `gamma` and any axes.
#[inline(always)]
pub fn axes_kernel_parts_n<A: AxisKernel>(
    gamma: f64,
    axes: &[A],
    n: usize,
    fx: &[[Real; FEATURES_PER_JOINT]],
    fxp: &[[Real; FEATURES_PER_JOINT]],
    first: &mut [Real; MAX_JOINTS],
    second: &mut [Real; MAX_JOINTS],
) -> Real {
    let mut exponent = 0.0;
    let axes = first.iter_mut().zip(second.iter_mut()).zip(axes.iter().zip(fx.iter().zip(fxp.iter())));
    for ((f1, f2), (axis, (a, b))) in axes.take(n) {
        let (f, df, ddf) = axis.terms(a, b);
        exponent += f;
        *f1 = df;
        *f2 = ddf;
    }
    gamma as Real * exp(exponent)
}

/// Σ_d f_d(x_d − x'_d) over at most `n` axes, K_V = γ e^{that} ([`joint_kernel_parts_n`]'s exponent, the same sum).
#[inline(always)]
pub fn joint_kernel_exponent_n<K: JointAxes + ?Sized>(
    kernel: &K,
    n: usize,
    fx: &[[Real; FEATURES_PER_JOINT]],
    fxp: &[[Real; FEATURES_PER_JOINT]],
) -> Real {
    let mut exponent = 0.0;
    for (axis, (a, b)) in kernel.axes().iter().zip(fx.iter().zip(fxp.iter())).take(n) {
        exponent += axis.terms(a, b).0;
    }
    exponent
}

/// K_V(x, x') and its gradient with respect to x (`grad_d = K f'_d`) from [`joint_features`].
#[inline]
pub fn joint_kernel_from_features<K: JointAxes + ?Sized>(
    kernel: &K,
    fx: &[[Real; FEATURES_PER_JOINT]],
    fxp: &[[Real; FEATURES_PER_JOINT]],
    grad: &mut [Real; MAX_JOINTS],
) -> Real {
    let mut second = [0.0; MAX_JOINTS];
    let value = joint_kernel_parts(kernel, fx, fxp, grad, &mut second);
    for g in grad.iter_mut().take(kernel.axes().len()) {
        *g *= value;
    }
    value
}

/// K_V(x, x') = γ exp(Σ_d f_d(x_d − x'_d)) and its gradient with respect to x.
/// f_d the axis form's ([`AxisKernel::terms`]). The same arithmetic as
/// [`joint_kernel_from_features`] (which the flows use), so every caller gets identical values.
#[inline]
pub fn joint_kernel<K: JointAxes + ?Sized>(kernel: &K, x: &[f64], xp: &[f64], grad: &mut [Real; MAX_JOINTS]) -> Real {
    let mut fx = [[0.0; FEATURES_PER_JOINT]; MAX_JOINTS];
    let mut fxp = [[0.0; FEATURES_PER_JOINT]; MAX_JOINTS];
    joint_features(kernel, x, &mut fx);
    joint_features(kernel, xp, &mut fxp);
    joint_kernel_from_features(kernel, &fx, &fxp, grad)
}

/// K_W(y, y') = exp(−|y − y'|²/(2a²)) with y − y' = `diff`; also returns the gradient
/// with respect to y, −K e / a².
#[inline]
pub fn task_kernel(kernel: &TaskKernel, diff: &[Real; MAX_TASK_DIM], m: usize, grad: &mut [Real; MAX_TASK_DIM]) -> Real {
    let width = kernel.width as Real;
    let inv_a2 = 1.0 / (width * width);
    let mut r2 = 0.0;
    for e in diff.iter().take(m) {
        r2 += e * e;
    }
    let value = exp(-0.5 * r2 * inv_a2);
    for (g, e) in grad.iter_mut().zip(diff.iter()).take(m) {
        *g = -value * *e * inv_a2;
    }
    value
}

#[cfg(test)]
mod tests {
    use super::*;
    use heapless::Vec as HVec;

    fn mixed_kernel() -> JointKernel {
        JointKernel {
            gamma: 3.0,
            axes: HVec::from_slice(&[
                JointKernelAxis::Periodic { b: 1.3 },
                JointKernelAxis::Gaussian { width: 0.7 },
                JointKernelAxis::Periodic { b: 0.4 },
            ])
            .unwrap(),
        }
    }

    #[test]
    #[cfg_attr(feature = "f32", ignore = "f64 reference at f64 tolerance (the f32 build's accuracy: the firmware's f32 rows)")]
    fn joint_kernel_gradient_matches_finite_differences() {
        let k = mixed_kernel();
        let x = [0.3, -0.2, 2.9];
        let xp = [1.1, 0.4, -2.5];
        let mut g = [0.0; MAX_JOINTS];
        let v = joint_kernel(&k, &x, &xp, &mut g);
        assert!(v > 0.0 && v <= 3.0);
        let h = 1e-6;
        for d in 0..3 {
            let mut xa = x;
            let mut xb = x;
            xa[d] += h;
            xb[d] -= h;
            let mut s = [0.0; MAX_JOINTS];
            let fd = (joint_kernel(&k, &xa, &xp, &mut s) - joint_kernel(&k, &xb, &xp, &mut s)) / (2.0 * h) as Real;
            assert!((fd - g[d]).abs() < 1e-8 * (1.0 + fd.abs()), "axis {d}: {fd} vs {}", g[d]);
        }
    }

    #[test]
    fn periodic_axes_are_periodic() {
        let k = mixed_kernel();
        let mut g = [0.0; MAX_JOINTS];
        let a = joint_kernel(&k, &[0.3, 0.1, 1.0], &[1.0, 0.2, -1.0], &mut g);
        let b = joint_kernel(&k, &[0.3 + 2.0 * core::f64::consts::PI, 0.1, 1.0], &[1.0, 0.2, -1.0], &mut g);
        assert!((a - b).abs() < 1e-12);
    }

    #[test]
    #[cfg_attr(feature = "f32", ignore = "f64 reference at f64 tolerance (the f32 build's accuracy: the firmware's f32 rows)")]
    fn task_kernel_gradient_matches_finite_differences() {
        let k = TaskKernel { width: 0.8 };
        let e: [Real; 3] = [0.3, -0.5, 0.2];
        let mut g = [0.0; MAX_TASK_DIM];
        task_kernel(&k, &e, 3, &mut g);
        let h = 1e-6;
        for c in 0..3 {
            let mut ea = e;
            let mut eb = e;
            ea[c] += h;
            eb[c] -= h;
            let mut s = [0.0; MAX_TASK_DIM];
            let fd = (task_kernel(&k, &ea, 3, &mut s) - task_kernel(&k, &eb, 3, &mut s)) / (2.0 * h as Real);
            assert!((fd - g[c]).abs() < 1e-9);
        }
    }

    #[test]
    #[cfg_attr(feature = "f32", ignore = "f64 reference at f64 tolerance (the f32 build's accuracy: the firmware's f32 rows)")]
    fn features_give_the_direct_formula() {
        // Independent check: γ exp(Σ b (cos(x − x') − 1) − Σ Δ²/(2ℓ²)) with cos of the difference.
        let k = mixed_kernel();
        let (x, xp) = ([0.3, -0.2, 2.9], [1.1, 0.4, -2.5]);
        let mut g = [0.0; MAX_JOINTS];
        let v = joint_kernel(&k, &x, &xp, &mut g);
        let direct =
            3.0 * libm::exp(1.3 * (libm::cos(0.3 - 1.1) - 1.0) - 0.5 * 0.6 * 0.6 / (0.7 * 0.7) + 0.4 * (libm::cos(2.9 + 2.5) - 1.0));
        assert!((v as f64 - direct).abs() < 1e-15 * direct, "{v} vs {direct}");
        let (mut fx, mut fxp) = ([[0.0; FEATURES_PER_JOINT]; MAX_JOINTS], [[0.0; FEATURES_PER_JOINT]; MAX_JOINTS]);
        joint_features(&k, &x, &mut fx);
        joint_features(&k, &xp, &mut fxp);
        let mut g2 = [0.0; MAX_JOINTS];
        assert_eq!(joint_kernel_from_features(&k, &fx, &fxp, &mut g2).to_bits(), v.to_bits());
        assert_eq!(g2.map(Real::to_bits), g.map(Real::to_bits));
    }
}

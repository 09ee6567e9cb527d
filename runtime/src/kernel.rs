//! The two reproducing kernels: K_V on joint space, K_W on task space (DESIGN.md §2).

use cbd_protocol::{JointKernel, JointKernelAxis, TaskKernel, MAX_JOINTS, MAX_TASK_DIM};

/// K_V(x, x') = γ exp(Σ_d f_d(x_d − x'_d)) and its gradient with respect to x.
/// f_d = b (cos Δ − 1) on periodic axes, −Δ²/(2ℓ²) on Gaussian axes.
#[inline]
pub fn joint_kernel(kernel: &JointKernel, x: &[f64], xp: &[f64], grad: &mut [f64; MAX_JOINTS]) -> f64 {
    let mut exponent = 0.0;
    for (g, (axis, (a, b))) in grad.iter_mut().zip(kernel.axes.iter().zip(x.iter().zip(xp.iter()))) {
        let delta = a - b;
        let (f, df) = match *axis {
            JointKernelAxis::Periodic { b } => (b * (libm::cos(delta) - 1.0), -b * libm::sin(delta)),
            JointKernelAxis::Gaussian { width } => {
                let s = 1.0 / (width * width);
                (-0.5 * delta * delta * s, -delta * s)
            }
        };
        exponent += f;
        *g = df;
    }
    let value = kernel.gamma * libm::exp(exponent);
    for g in grad.iter_mut().take(kernel.axes.len()) {
        *g *= value;
    }
    value
}

/// K_W(y, y') = exp(−|y − y'|²/(2a²)) with y − y' = `diff`; also returns the gradient
/// with respect to y, −K e / a².
#[inline]
pub fn task_kernel(kernel: &TaskKernel, diff: &[f64; MAX_TASK_DIM], m: usize, grad: &mut [f64; MAX_TASK_DIM]) -> f64 {
    let inv_a2 = 1.0 / (kernel.width * kernel.width);
    let mut r2 = 0.0;
    for e in diff.iter().take(m) {
        r2 += e * e;
    }
    let value = libm::exp(-0.5 * r2 * inv_a2);
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
            let fd = (joint_kernel(&k, &xa, &xp, &mut s) - joint_kernel(&k, &xb, &xp, &mut s)) / (2.0 * h);
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
    fn task_kernel_gradient_matches_finite_differences() {
        let k = TaskKernel { width: 0.8 };
        let e = [0.3, -0.5, 0.2];
        let mut g = [0.0; MAX_TASK_DIM];
        task_kernel(&k, &e, 3, &mut g);
        let h = 1e-6;
        for c in 0..3 {
            let mut ea = e;
            let mut eb = e;
            ea[c] += h;
            eb[c] -= h;
            let mut s = [0.0; MAX_TASK_DIM];
            let fd = (task_kernel(&k, &ea, 3, &mut s) - task_kernel(&k, &eb, 3, &mut s)) / (2.0 * h);
            assert!((fd - g[c]).abs() < 1e-9);
        }
    }
}

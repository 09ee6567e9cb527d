extern crate std;
use super::*;
use cbd_protocol::MAX_JOINTS;
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

/// Codes for the mixed kernel: every combination of a few orders, including the highest.
fn mixed_codes() -> ([u8; 3 * 64], usize) {
    let mut codes = [0u8; 3 * 64];
    let mut r = 0;
    for (h0, s0) in [(0, 0), (1, 1), (3, 0), (7, 1), (63, 0)] {
        for k in [0u8, 1, 2, 5, 11] {
            for (h2, s2) in [(0, 0), (2, 1), (5, 0)] {
                if r < 64 {
                    codes[3 * r..3 * r + 3].copy_from_slice(&[h0 << 1 | s0, k << 1, h2 << 1 | s2]);
                    r += 1;
                }
            }
        }
    }
    (codes, r)
}

/// The direct formula: libm cos/sin per harmonic, exp and powers for the Hermite functions.
fn direct_joint(kernel: &JointKernel, codes: &[u8], x: &[f64]) -> f64 {
    let mut v = 1.0;
    for ((axis, &c), &xd) in kernel.axes.iter().zip(codes).zip(x) {
        let k = (c >> 1) as i32;
        v *= match *axis {
            JointKernelAxis::Periodic { .. } => {
                if c & 1 == 1 {
                    libm::sin(k as f64 * xd)
                } else {
                    libm::cos(k as f64 * xd)
                }
            }
            JointKernelAxis::Gaussian { width } => {
                let u = xd / width;
                let fact: f64 = (1..=k).map(|i| i as f64).product();
                libm::exp(-0.5 * u * u) * libm::pow(u, k as f64) / libm::sqrt(fact)
            }
        };
    }
    v
}

fn joint_rows(x: &[f64], hessian: bool) -> ([f64; 64 * 13], usize) {
    let (codes, r) = mixed_codes();
    let mut rows = [0.0; 64 * 13];
    write_joint_basis(&mixed_kernel(), &codes[..3 * r], 3, x, &mut rows[..r * joint_row_len(3)], hessian);
    (rows, r)
}

#[test]
fn tables_are_the_correctly_rounded_roots() {
    for k in 0..ORDERS {
        assert_eq!(SQRT[k].to_bits(), (k as f64).sqrt().to_bits(), "√{k}");
        if k > 0 {
            let reference = 1.0 / (k as f64).sqrt();
            assert!((INV_SQRT[k] - reference).abs() <= f64::EPSILON * reference, "1/√{k}");
        }
    }
}

#[test]
fn joint_values_match_the_direct_formula() {
    let kernel = mixed_kernel();
    let (codes, r) = mixed_codes();
    for x in [[0.3, -0.2, 2.9], [-3.1, 1.4, 0.01], [1.0e-3, -2.5, -1.7]] {
        let (rows, _) = joint_rows(&x, true);
        for f in 0..r {
            let direct = direct_joint(&kernel, &codes[3 * f..3 * f + 3], &x);
            let got = rows[f * joint_row_len(3)];
            let h = codes[3 * f..3 * f + 3].iter().map(|c| (c >> 1) as f64).sum::<f64>();
            // The recurrence's error grows with the harmonic: a few ulps × h (of the factors' scale).
            assert!((got - direct).abs() <= 8.0 * f64::EPSILON * (1.0 + h), "x {x:?}, row {f}: {got} vs {direct}");
        }
    }
}

#[test]
fn joint_gradients_and_hessians_match_finite_differences() {
    let (_, r) = mixed_codes();
    let x = [0.3, -0.2, 2.9];
    let (rows, _) = joint_rows(&x, true);
    let len = joint_row_len(3);
    let eps = 1e-6;
    for d in 0..3 {
        let (mut xp, mut xm) = (x, x);
        xp[d] += eps;
        xm[d] -= eps;
        let (rp, _) = joint_rows(&xp, true);
        let (rm, _) = joint_rows(&xm, true);
        for f in 0..r {
            let row = &rows[f * len..(f + 1) * len];
            // Scale: the highest harmonic h makes derivatives h and h² larger.
            let fd = (rp[f * len] - rm[f * len]) / (2.0 * eps);
            let grad = row[1 + d];
            assert!((fd - grad).abs() < 1e-6 * (1.0 + fd.abs()) * 64.0, "row {f} ∂{d}: {grad} vs {fd}");
            for e in 0..3 {
                let fd = (rp[f * len + 1 + e] - rm[f * len + 1 + e]) / (2.0 * eps);
                let h = row[1 + 3 + d * 3 + e];
                assert!((fd - h).abs() < 1e-5 * (1.0 + fd.abs()) * 64.0, "row {f} ∂{d}∂{e}: {h} vs {fd}");
                assert_eq!(h.to_bits(), row[1 + 3 + e * 3 + d].to_bits(), "symmetric");
            }
        }
    }
}

#[test]
fn without_the_hessian_the_second_derivatives_are_untouched_and_the_rest_identical() {
    let (codes, r) = mixed_codes();
    let x = [0.3, -0.2, 2.9];
    let (full, _) = joint_rows(&x, true);
    let mut rows = [7.0; 64 * 13];
    write_joint_basis(&mixed_kernel(), &codes[..3 * r], 3, &x, &mut rows[..r * 13], false);
    for f in 0..r {
        assert_eq!(
            rows[f * 13..f * 13 + 4].iter().map(|v| v.to_bits()).collect::<std::vec::Vec<_>>(),
            full[f * 13..f * 13 + 4].iter().map(|v| v.to_bits()).collect::<std::vec::Vec<_>>()
        );
        assert!(rows[f * 13 + 4..(f + 1) * 13].iter().all(|v| *v == 7.0));
    }
}

#[test]
fn periodic_axes_are_periodic() {
    let (_, r) = mixed_codes();
    let x = [0.3, -0.2, 2.9];
    let (a, _) = joint_rows(&x, true);
    let two_pi = 2.0 * core::f64::consts::PI;
    let (b, _) = joint_rows(&[x[0] + two_pi, x[1], x[2] - two_pi], true);
    for i in 0..r * 13 {
        assert!((a[i] - b[i]).abs() < 1e-10 * (1.0 + a[i].abs()) * 64.0 * 64.0, "{i}: {} vs {}", a[i], b[i]);
    }
}

const EXPONENTS: [u8; 3 * 8] = [0, 0, 0, 1, 0, 0, 0, 2, 1, 3, 1, 4, 0, 0, 9, 2, 2, 2, 12, 0, 1, 63, 0, 0];

fn direct_task(a: f64, alpha: &[u8], y: &[f64]) -> f64 {
    let mut v = 1.0;
    for (&k, &yc) in alpha.iter().zip(y) {
        let u = yc / a;
        let fact: f64 = (1..=k as i32).map(|i| i as f64).product();
        v *= libm::exp(-0.5 * u * u) * libm::pow(u, k as f64) / libm::sqrt(fact);
    }
    v
}

fn task_values(a: f64, y: &[f64; 3], hessian: bool) -> std::vec::Vec<(f64, [f64; 3], [[f64; 3]; 3])> {
    let mut out = std::vec::Vec::new();
    for_each_task_basis(&TaskKernel { width: a }, &EXPONENTS, 3, y, hessian, |g, psi, grad, hess| {
        assert_eq!(g, out.len());
        out.push((psi, *grad, *hess));
    });
    out
}

#[test]
fn task_values_gradients_and_hessians() {
    let a = 0.8;
    let y = [0.3, -0.5, 0.9];
    let values = task_values(a, &y, true);
    assert_eq!(values.len(), 8);
    let eps = 1e-6;
    for (g, (psi, grad, hess)) in values.iter().enumerate() {
        let direct = direct_task(a, &EXPONENTS[3 * g..3 * g + 3], &y);
        assert!((psi - direct).abs() <= 1e-14 * (1.0 + direct.abs()), "ψ_{g}: {psi} vs {direct}");
        for c in 0..3 {
            let (mut yp, mut ym) = (y, y);
            yp[c] += eps;
            ym[c] -= eps;
            let (vp, vm) = (task_values(a, &yp, true), task_values(a, &ym, true));
            let fd = (vp[g].0 - vm[g].0) / (2.0 * eps);
            assert!((fd - grad[c]).abs() < 1e-7 * (1.0 + fd.abs()), "∂{c}ψ_{g}: {} vs {fd}", grad[c]);
            for b in 0..3 {
                let fd = (vp[g].1[b] - vm[g].1[b]) / (2.0 * eps);
                assert!((fd - hess[c][b]).abs() < 1e-6 * (1.0 + fd.abs()), "∂{c}∂{b}ψ_{g}: {} vs {fd}", hess[c][b]);
            }
        }
    }
    for (g, (psi, grad, hess)) in task_values(a, &y, false).iter().enumerate() {
        assert_eq!((psi.to_bits(), grad.map(f64::to_bits)), (values[g].0.to_bits(), values[g].1.map(f64::to_bits)));
        assert_eq!(*hess, [[0.0; 3]; 3]);
    }
}

#[test]
fn far_points_give_zeros_not_nans() {
    let values = task_values(0.1, &[1e6, -3e5, 40.0], true);
    assert!(values.iter().all(|(p, g, h)| *p == 0.0 && g.iter().all(|v| *v == 0.0) && h.iter().flatten().all(|v| *v == 0.0)));
    let (rows, r) = joint_rows(&[0.3, 1e6, 1e9], true);
    assert!(rows[..r * 13].iter().all(|v| v.is_finite()));
    let _ = MAX_JOINTS;
}

extern crate std;
use super::*;
use cbd_protocol::{JointKernelAxis, MAX_JOINTS};
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
    // Low orders (every axis's tables at once), two joints: the same.
    let kernel = kernel_of(2);
    let codes: std::vec::Vec<u8> = (0..20u8).flat_map(|f| [(f % 8) << 1 | (f % 8 > 0 && f % 2 == 1) as u8, (f % 5) << 1]).collect();
    let (mut full, mut rows) = ([0.0; 20 * 7], [7.0; 20 * 7]);
    write_joint_basis(&kernel, &codes, 2, &[0.4, -1.3], &mut full, true);
    write_joint_basis(&kernel, &codes, 2, &[0.4, -1.3], &mut rows, false);
    for (f, r) in full.chunks_exact(7).zip(rows.chunks_exact(7)) {
        assert_eq!(bits(&r[..3]), bits(&f[..3]));
        assert!(r[3..].iter().all(|v| *v == 7.0));
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

/// The basis as computed before the factor tables (per row and function: a Hermite or harmonic
/// table lookup, the factor's formula, the product rule over rows of running products): the
/// reference the tables must reproduce bit for bit.
mod reference {
    use super::super::{Scalar, INV_SQRT, ORDERS, SQRT};
    use crate::real::Real;
    use cbd_protocol::{code_is_sin, code_order, JointKernel, JointKernelAxis, TaskKernel, MAX_TASK_DIM as MT};

    fn hermite_table<T: Scalar>(u: T, order: usize, q: &mut [T; ORDERS]) {
        let mut prev = (T::of(-0.5) * u * u).exp();
        for (k, (dst, inv_sqrt)) in q.iter_mut().zip(INV_SQRT.iter()).enumerate().take(order + 1) {
            if k > 0 {
                prev = prev * u * T::of(*inv_sqrt);
            }
            *dst = prev;
        }
    }

    fn hermite_factor<T: Scalar>(q: &[T; ORDERS], k: usize, u: T) -> (T, T, T) {
        let at = |i: Option<usize>| i.and_then(|i| q.get(i)).copied().unwrap_or(T::ZERO);
        let sqrt = |i: usize| T::of(SQRT.get(i).copied().unwrap_or(0.0));
        let (q0, q1, q2) = (at(Some(k)), at(k.checked_sub(1)), at(k.checked_sub(2)));
        let raised = sqrt(k) * q1;
        let first = raised - u * q0;
        let second = sqrt(k) * sqrt(k.saturating_sub(1)) * q2 - T::of(2.0) * u * raised + (u * u - T::ONE) * q0;
        (q0, first, second)
    }

    fn multiply_factor(phi: &mut Real, grad: &mut [Real], hess: Option<&mut [Real]>, n: usize, d: usize, f: [Real; 3]) {
        let [f0, f1, f2] = f;
        let p = *phi;
        if let Some(hess) = hess {
            for (e, h_row) in hess.chunks_exact_mut(n).enumerate().take(d + 1) {
                let g_e = grad[e];
                for (e2, h) in h_row.iter_mut().enumerate().take(d + 1) {
                    *h = match (e == d, e2 == d) {
                        (false, false) => *h * f0,
                        (false, true) => g_e * f1,
                        (true, false) => grad[e2] * f1,
                        (true, true) => p * f2,
                    };
                }
            }
        }
        for (e, g) in grad.iter_mut().enumerate().take(d + 1) {
            *g = if e == d { p * f1 } else { *g * f0 };
        }
        *phi = p * f0;
    }

    fn axis_order(orders: impl Iterator<Item = u8>) -> usize {
        orders.max().map_or(0, |o| o.min(63)) as usize
    }

    pub fn joint_basis(joint_kernel: &JointKernel, codes: &[u8], n: usize, x: &[f64], rows: &mut [Real], hessian: bool) {
        let row_len = 1 + n + n * n;
        for row in rows.chunks_exact_mut(row_len) {
            row[0] = 1.0;
        }
        for (d, (axis, &xd)) in joint_kernel.axes.iter().zip(x.iter()).enumerate().take(n) {
            let order = axis_order(codes.chunks_exact(n).map(|c| code_order(c[d])));
            let (mut cos, mut sin) = ([0.0f64; ORDERS], [0.0f64; ORDERS]);
            let (u, inv_width) = match *axis {
                JointKernelAxis::Periodic { .. } => {
                    let (s1, c1) = libm::sincos(xd);
                    let (mut c, mut s) = (1.0, 0.0);
                    for (ch, sh) in cos.iter_mut().zip(sin.iter_mut()).take(order + 1) {
                        (*ch, *sh) = (c, s);
                        (c, s) = (c * c1 - s * s1, s * c1 + c * s1);
                    }
                    (0.0, 0.0)
                }
                JointKernelAxis::Gaussian { width } => {
                    let u = xd / width;
                    hermite_table(u, order, &mut cos);
                    (u, 1.0 / width)
                }
            };
            for (row, code_row) in rows.chunks_exact_mut(row_len).zip(codes.chunks_exact(n)) {
                let code = code_row[d];
                let k = code_order(code) as usize;
                let (f0, f1, f2) = match *axis {
                    JointKernelAxis::Periodic { .. } => {
                        let h = k as f64;
                        let (c, s) = (cos[k], sin[k]);
                        if code_is_sin(code) {
                            (s, h * c, -(h * h) * s)
                        } else {
                            (c, -h * s, -(h * h) * c)
                        }
                    }
                    JointKernelAxis::Gaussian { .. } => {
                        let (f0, f1, f2) = hermite_factor(&cos, k, u);
                        (f0, f1 * inv_width, f2 * (inv_width * inv_width))
                    }
                };
                let (phi, rest) = row.split_first_mut().unwrap();
                let (grad, hess) = rest.split_at_mut(n);
                multiply_factor(phi, grad, if hessian { Some(hess) } else { None }, n, d, [f0 as Real, f1 as Real, f2 as Real]);
            }
        }
    }

    pub fn task_basis(
        task_kernel: &TaskKernel,
        exponents: &[u8],
        m: usize,
        y: &[Real],
        hessian: bool,
        mut each: impl FnMut(usize, Real, &[Real; MT], &[[Real; MT]; MT]),
    ) {
        let inv_a = 1.0 / task_kernel.width as Real;
        let mut u = [0.0 as Real; MT];
        let mut tables = [[0.0 as Real; ORDERS]; MT];
        for c in 0..m {
            u[c] = y[c] * inv_a;
            let order = axis_order(exponents.chunks_exact(m).map(|e| e[c]));
            hermite_table(u[c], order, &mut tables[c]);
        }
        let inv_a2 = inv_a * inv_a;
        for (g, alpha) in exponents.chunks_exact(m).enumerate() {
            let (mut psi, mut grad, mut hess) = (1.0 as Real, [0.0 as Real; MT], [0.0 as Real; MT * MT]);
            for (c, a) in alpha.iter().enumerate() {
                let (f0, f1, f2) = hermite_factor(&tables[c], *a as usize, u[c]);
                multiply_factor(&mut psi, &mut grad, if hessian { Some(&mut hess[..]) } else { None }, m, c, [f0, f1 * inv_a, f2 * inv_a2]);
            }
            let mut hess_rows = [[0.0 as Real; MT]; MT];
            if hessian {
                for c in 0..m {
                    hess_rows[c][..m].copy_from_slice(&hess[c * m..(c + 1) * m]);
                }
            }
            each(g, psi, &grad, &hess_rows);
        }
    }
}

fn bits(v: &[Real]) -> std::vec::Vec<u64> {
    v.iter().map(|x| x.to_bits() as u64).collect()
}

/// A kernel of n axes, periodic and Gaussian mixed (n = 3: [`mixed_kernel`]).
fn kernel_of(n: usize) -> JointKernel {
    if n == 3 {
        return mixed_kernel();
    }
    let axes = (0..n).map(|d| {
        if d % 3 == 1 {
            JointKernelAxis::Gaussian { width: 0.7 + 0.2 * d as f64 }
        } else {
            JointKernelAxis::Periodic { b: 0.5 }
        }
    });
    JointKernel { gamma: 2.0, axes: axes.collect() }
}

/// Low-order codes only (every axis's tables at once, rows formed in registers) and with one row of
/// high orders appended (one axis at a time, tables of every order), for n = 2 and 6 (loops shaped
/// at compile time) and n = 1, 3, 7, 10, 16: rows, gradients and Hessians bit for bit as the reference
/// computes them, and the common rows the same in both.
#[test]
fn joint_tables_reproduce_the_reference_bit_for_bit() {
    // (10 joints need the feature `long-chains`: a default build holds MAX_JOINTS = 7.)
    for n in [1, 2, 3, 6, 7, 10, MAX_JOINTS].into_iter().filter(|&n| n <= MAX_JOINTS) {
        let kernel = kernel_of(n);
        // Orders 0..15 on every axis (the small tables' limit is 16), the sine bit on periodic axes only.
        let mut low = std::vec::Vec::new();
        for f in 0..48usize {
            for (d, axis) in kernel.axes.iter().enumerate() {
                let h = ((f * (2 * d + 3) + d) % 16) as u8;
                let s = matches!(axis, JointKernelAxis::Periodic { .. }) && h > 0 && (f + d) % 2 == 1;
                low.push(h << 1 | s as u8);
            }
        }
        let mut high = low.clone();
        high.extend((0..n).map(|d| [16u8 << 1, 40 << 1, 63 << 1][d % 3]));
        let len = joint_row_len(n);
        let xs = [
            [0.3, -0.2, 2.9, 1.1, -0.4, 0.8, -2.2, 1.7, -0.9, 0.45, -2.7, 2.2, -1.3, 0.15, 3.05, -0.6],
            [-3.1, 1.4, 0.01, -0.7, 2.5, -1.9, 0.6, -0.25, 1.95, -2.4, 0.85, -1.1, 2.75, -0.05, -1.6, 1.2],
            [1.0e-3, -2.5, -1.7, 0.2, 3.0, 0.05, -1.0, 2.6, -0.35, 1.3, -2.9, 0.7, -1.45, 2.05, 0.55, -3.0],
        ];
        for x in xs.iter().map(|x| &x[..n]) {
            for hessian in [true, false] {
                for codes in [&low, &high] {
                    let r = codes.len() / n;
                    let (mut got, mut want) = (std::vec![0.0 as Real; r * len], std::vec![0.0 as Real; r * len]);
                    write_joint_basis(&kernel, codes, n, x, &mut got, hessian);
                    reference::joint_basis(&kernel, codes, n, x, &mut want, hessian);
                    if !hessian {
                        // Without the Hessian its part is left as it was: compare the rest.
                        for (g, w) in got.chunks_exact_mut(len).zip(want.chunks_exact_mut(len)) {
                            g[1 + n..].fill(0.0);
                            w[1 + n..].fill(0.0);
                        }
                    }
                    assert_eq!(bits(&got), bits(&want), "n {n}, x {x:?}, hessian {hessian}, {r} rows");
                    let mut with_orders = std::vec![0.0 as Real; r * len];
                    write_joint_basis_with_orders(&kernel, codes, &joint_orders(codes, n), n, x, &mut with_orders, hessian);
                    if !hessian {
                        for row in with_orders.chunks_exact_mut(len) {
                            row[1 + n..].fill(0.0);
                        }
                    }
                    assert_eq!(bits(&with_orders), bits(&got));
                }
                let (mut a, mut b) = (std::vec![0.0 as Real; high.len() / n * len], std::vec![0.0 as Real; low.len() / n * len]);
                write_joint_basis(&kernel, &high, n, x, &mut a, hessian);
                write_joint_basis(&kernel, &low, n, x, &mut b, hessian);
                assert_eq!(bits(&a[..b.len()]), bits(&b));
            }
        }
    }
}

/// The task basis with small and full tables: ψ, ∇ψ, ∇²ψ bit for bit as the reference computes them.
#[test]
fn task_tables_reproduce_the_reference_bit_for_bit() {
    let mut low = std::vec::Vec::new();
    for g in 0..40u32 {
        low.extend_from_slice(&[(g * 7 % 16) as u8, (g * 3 % 16) as u8, (g * 11 % 16) as u8]);
    }
    let mut high = low.clone();
    high.extend_from_slice(&[16, 2, 63]);
    let collect = |basis: &dyn Fn(&mut dyn FnMut(usize, Real, &[Real; MT], &[[Real; MT]; MT]))| {
        let mut out = std::vec::Vec::new();
        basis(&mut |g, psi, grad, hess| {
            assert_eq!(g, out.len() / 13);
            out.push(psi);
            out.extend_from_slice(grad);
            out.extend(hess.iter().flatten());
        });
        out
    };
    for (a, y) in [(0.8, [0.3 as Real, -0.5, 0.9]), (1.9, [-1.2, 0.05, 2.5]), (0.2, [0.01, -0.03, 0.02])] {
        let kernel = TaskKernel { width: a };
        for hessian in [true, false] {
            for m in [1, 2, 3] {
                for exps in [&low, &high] {
                    let exps: std::vec::Vec<u8> = exps.chunks_exact(3).flat_map(|e| e[..m].iter().copied()).collect();
                    let got = collect(&|each| for_each_task_basis(&kernel, &exps, m, &y, hessian, each));
                    let want = collect(&|each| reference::task_basis(&kernel, &exps, m, &y, hessian, each));
                    assert_eq!(bits(&got), bits(&want), "a {a}, m {m}, hessian {hessian}");
                    let orders = task_orders(&exps, m);
                    let with_orders = collect(&|each| for_each_task_basis_with_orders(&kernel, &exps, &orders, m, &y, hessian, each));
                    assert_eq!(bits(&with_orders), bits(&got));
                }
            }
        }
    }
}

//! The basis functions of the fields' expansions (format 5, docs/DESIGN.md §11): the joint basis
//! φ_f(x) = Π_d F_d(x_d) (each axis form's own factors, `crate::kernel::axis`: periodic axes
//! cos(h x)/sin(h x), Gaussian axes the Hermite functions e^{−u²/2} u^k/√(k!), u = x/ℓ) and the task basis ψ_g(y) = Π_c e^{−u_c²/2} u_c^{α_c}/√(α_c!), u = y/a,
//! with their gradients and Hessians. The trainer builds its design matrices with these same
//! functions, so trainer and runtime use the same bits.

use crate::flow::Shape;
use crate::kernel::axis::AxisKernel;
use crate::kernel::hermite::{hermite_factors, ORDERS};
#[cfg(all(test, not(feature = "f32")))]
use crate::kernel::hermite::{Scalar, INV_SQRT, SQRT};
use crate::real::Real;
use cbd_protocol::{code_order, JointKernel, TaskKernel, MAX_EXPANSION_ORDER, MAX_JOINTS as NJ, MAX_TASK_DIM as MT};

/// Values per joint-basis row: φ, ∇φ (n), ∇²φ (n×n) — the layout of the query's kernel rows.
pub const fn joint_row_len(n: usize) -> usize {
    1 + n + n * n
}

/// Multiplies factor `f` = (F, F', F'') of axis d into a product basis function's running value,
/// gradient and (HESSIAN, row-major, rows of `stride`) Hessian: the product rule, axis by axis. Before the call
/// the entries of axes below d hold the product of factors 0..d; after it those of axes up to d.
/// The first factor (d = 0) is written as it is: the product before it is 1, and 1 · F = F exactly.
#[inline(always)]
fn multiply_factor<const HESSIAN: bool>(phi: &mut Real, grad: &mut [Real], hess: &mut [Real], stride: usize, d: usize, f: [Real; 3]) {
    let [f0, f1, f2] = f;
    if d == 0 {
        *phi = f0;
        if let Some(g) = grad.first_mut() {
            *g = f1;
        }
        if HESSIAN {
            if let Some(h) = hess.first_mut() {
                *h = f2;
            }
        }
        return;
    }
    let p = *phi;
    if HESSIAN {
        // ∂_e ∂_e' (φ F) = F ∂_e ∂_e' φ (e, e' < d); ∂_e ∂_d = F' ∂_e φ; ∂_d ∂_d = F'' φ. Rows by
        // splitting (an iterator zip over `chunks_exact` keeps a division-by-zero panic path).
        let mut h_rows: &mut [Real] = hess;
        for g_e in grad.iter().take(d) {
            let Some((h_row, rest)) = core::mem::take(&mut h_rows).split_at_mut_checked(stride) else { break };
            h_rows = rest;
            let Some((left, right)) = h_row.split_at_mut_checked(d) else { break };
            for h in left.iter_mut() {
                *h *= f0;
            }
            if let Some(h) = right.first_mut() {
                *h = g_e * f1;
            }
        }
        if let Some((left, right)) = h_rows.split_at_mut_checked(d) {
            for (h, g) in left.iter_mut().zip(grad.iter()) {
                *h = g * f1;
            }
            if let Some(h) = right.first_mut() {
                *h = p * f2;
            }
        }
    }
    if let Some((left, right)) = grad.split_at_mut_checked(d) {
        for g in left.iter_mut() {
            *g *= f0;
        }
        if let Some(g) = right.first_mut() {
            *g = p * f1;
        }
    }
    *phi = p * f0;
}

/// The largest order in `orders`, at most MAX_EXPANSION_ORDER.
fn max_order(orders: impl Iterator<Item = u8>) -> u8 {
    orders.max().map_or(0, |o| o.min(MAX_EXPANSION_ORDER))
}

/// The highest order each axis of a joint expansion uses (`codes` rows of n; 0 for axes ≥ n).
pub fn joint_orders(codes: &[u8], n: usize) -> [u8; NJ] {
    core::array::from_fn(
        |d| if d < n { max_order(codes.chunks_exact(n.max(1)).filter_map(|c| c.get(d)).map(|&c| code_order(c))) } else { 0 },
    )
}

/// The highest exponent each coordinate of a task expansion uses (`exponents` rows of m; 0 for coordinates ≥ m).
pub fn task_orders(exponents: &[u8], m: usize) -> [u8; MT] {
    core::array::from_fn(|c| if c < m { max_order(exponents.chunks_exact(m.max(1)).filter_map(|e| e.get(c)).copied()) } else { 0 })
}

/// Orders up to which the factor tables of the common case are built; an expansion of higher
/// orders takes the tables of every order (a second instance of the loops).
const SMALL_ORDERS: usize = 16;

/// Every joint basis function at x (f64 joint values, rounded once to Real as kernel::joint_features does): rows of joint_row_len(n) values, r_V rows; with `hessian == false` the ∇² part is left untouched (may be garbage/zero).
/// Harmonics by recurrence from (cos x_d, sin x_d) computed in f64 (no sin/cos per term); Gaussian axes by the power recurrence.
///
/// r_V = `codes.len() / n`; rows beyond `rows.len() / joint_row_len(n)` are not written. Codes as
/// [`cbd_protocol::FieldExpansion::validate`] admits them (orders ≤ MAX_EXPANSION_ORDER). Per axis,
/// every code's factors F, F', F'' are computed once in f64 and rounded once to [`Real`] (tables of
/// 2 × 16 or, for higher orders, 2 × 64 codes on the stack); the products are formed axis by axis in [`Real`].
pub fn write_joint_basis(joint_kernel: &JointKernel, codes: &[u8], n: usize, x: &[f64], rows: &mut [Real], hessian: bool) {
    write_joint_basis_with_orders(joint_kernel, codes, &joint_orders(codes, n), n, x, rows, hessian)
}

/// [`write_joint_basis`] (bit-identical) with the axes' highest orders given ([`joint_orders`] of
/// `codes`, computed once per model).
pub fn write_joint_basis_with_orders(
    joint_kernel: &JointKernel,
    codes: &[u8],
    orders: &[u8; NJ],
    n: usize,
    x: &[f64],
    rows: &mut [Real],
    hessian: bool,
) {
    write_joint_basis_shaped(crate::flow::Dims { n, m: 0 }, joint_kernel, codes, orders, x, rows, hessian)
}

/// [`write_joint_basis_with_orders`] (bit-identical) with the loops shaped by `shape` (its n).
#[inline(always)]
pub(crate) fn write_joint_basis_shaped<S: Shape>(
    shape: S,
    joint_kernel: &JointKernel,
    codes: &[u8],
    orders: &[u8; NJ],
    x: &[f64],
    rows: &mut [Real],
    hessian: bool,
) {
    write_axes_basis_shaped(shape, &joint_kernel.axes, codes, orders, x, rows, hessian)
}

/// [`write_joint_basis_with_orders`] of any axes ([`AxisKernel::basis_factors`]).
pub fn write_axes_basis<A: AxisKernel>(axes: &[A], codes: &[u8], orders: &[u8; NJ], n: usize, x: &[f64], rows: &mut [Real], hessian: bool) {
    write_axes_basis_shaped(crate::flow::Dims { n, m: 0 }, axes, codes, orders, x, rows, hessian)
}

/// [`write_joint_basis_shaped`] of any axes.
#[inline(always)]
fn write_axes_basis_shaped<S: Shape, A: AxisKernel>(
    shape: S,
    axes: &[A],
    codes: &[u8],
    orders: &[u8; NJ],
    x: &[f64],
    rows: &mut [Real],
    hessian: bool,
) {
    // One instance per case: the flags' branches stay out of the per-row loop. Orders below
    // SMALL_ORDERS (the common case): every axis's tables at once, each row formed in registers,
    // for two and six joints with n known at compile time; higher orders: one axis at a time.
    let small = (orders.iter().copied().max().unwrap_or(0) as usize) < SMALL_ORDERS;
    let n = shape.n();
    match (hessian, small, n) {
        (true, true, 2) => joint_basis_rows::<true, 2, true, A>(2, axes, codes, orders, x, rows),
        (true, true, 6) => joint_basis_rows::<true, 6, true, A>(6, axes, codes, orders, x, rows),
        (true, true, _) => joint_basis_rows::<true, NJ, false, A>(n, axes, codes, orders, x, rows),
        (false, true, 2) => joint_basis_rows::<false, 2, true, A>(2, axes, codes, orders, x, rows),
        (false, true, 6) => joint_basis_rows::<false, 6, true, A>(6, axes, codes, orders, x, rows),
        (false, true, _) => joint_basis_rows::<false, NJ, false, A>(n, axes, codes, orders, x, rows),
        (true, false, _) => joint_basis_axes::<true, A>(n, axes, codes, orders, x, rows),
        (false, false, _) => joint_basis_axes::<false, A>(n, axes, codes, orders, x, rows),
    }
}

/// Codes `h << 1 | s` of orders below SMALL_ORDERS.
const SMALL_CODES: usize = 2 * SMALL_ORDERS;

/// The factors F, F', F'' (HESSIAN) of every code of one axis up to `order` (≤ CODES/2 − 1) at x_d
/// ([`AxisKernel::basis_factors`], in f64), rounded once to [`Real`]; entries above are left as they are.
#[inline(always)]
fn axis_factors<const HESSIAN: bool, const CODES: usize, A: AxisKernel>(
    axis: &A,
    xd: f64,
    order: usize,
    f0s: &mut [Real; CODES],
    f1s: &mut [Real; CODES],
    f2s: &mut [Real; CODES],
) {
    axis.basis_factors(xd, order, |code: usize, f0: f64, f1: f64, f2: f64| {
        if let (Some(d0), Some(d1), Some(d2)) = (f0s.get_mut(code), f1s.get_mut(code), f2s.get_mut(code)) {
            (*d0, *d1) = (f0 as Real, f1 as Real);
            if HESSIAN {
                *d2 = f2 as Real;
            }
        }
    });
}

/// The joint basis with every axis's factor tables at once (orders below SMALL_ORDERS): each row's
/// product, gradient and (HESSIAN) Hessian formed axis by axis in registers, then written once.
/// `EXACT`: n is AXES (loops unrolled); otherwise n ≤ AXES at run time.
#[inline(never)]
fn joint_basis_rows<const HESSIAN: bool, const AXES: usize, const EXACT: bool, A: AxisKernel>(
    n: usize,
    axes: &[A],
    codes: &[u8],
    orders: &[u8; NJ],
    x: &[f64],
    rows: &mut [Real],
) {
    let n = if EXACT { AXES } else { n.min(AXES) };
    let row_len = joint_row_len(n);
    if n == 0 {
        return;
    }
    // Per axis and code `h << 1 | s`: F, F', F''. A code of axis d is at most 2 order_d + 1.
    let (mut f0s, mut f1s, mut f2s) =
        ([[0.0 as Real; SMALL_CODES]; AXES], [[0.0 as Real; SMALL_CODES]; AXES], [[0.0 as Real; SMALL_CODES]; AXES]);
    let tables = f0s.iter_mut().zip(f1s.iter_mut()).zip(f2s.iter_mut());
    for (((axis, &xd), &order), ((t0, t1), t2)) in axes.iter().zip(x.iter()).zip(orders.iter()).zip(tables).take(n) {
        axis_factors::<HESSIAN, SMALL_CODES, A>(axis, xd, (order as usize).min(SMALL_ORDERS - 1), t0, t1, t2);
    }
    // Rows and codes walked by splitting (a zip of two `chunks_exact` keeps a division-by-zero
    // panic path the optimiser cannot remove).
    let mut code_rows = codes;
    for row in rows.chunks_exact_mut(row_len.max(1)) {
        let Some((code_row, rest)) = code_rows.split_at_checked(n) else { break };
        code_rows = rest;
        let (mut phi, mut grad, mut hess) = (0.0 as Real, [0.0 as Real; AXES], [[0.0 as Real; AXES]; AXES]);
        for (d, (&code, ((t0, t1), t2))) in code_row.iter().zip(f0s.iter().zip(f1s.iter()).zip(f2s.iter())).enumerate() {
            // Codes of this model are below SMALL_CODES: the remainder only spares the bounds checks.
            let k = code as usize % SMALL_CODES;
            let at = |t: &[Real; SMALL_CODES]| t.get(k).copied().unwrap_or(0.0);
            let f = [at(t0), at(t1), if HESSIAN { at(t2) } else { 0.0 }];
            multiply_factor::<HESSIAN>(&mut phi, &mut grad, hess.as_flattened_mut(), AXES, d, f);
        }
        let Some((row_phi, rest)) = row.split_first_mut() else { continue };
        let Some((row_grad, row_hess)) = rest.split_at_mut_checked(n) else { continue };
        *row_phi = phi;
        for (dst, src) in row_grad.iter_mut().zip(grad.iter()) {
            *dst = *src;
        }
        if HESSIAN {
            let mut dst_rows: &mut [Real] = row_hess;
            for src_row in hess.iter().take(n) {
                let Some((dst_row, rest)) = core::mem::take(&mut dst_rows).split_at_mut_checked(n) else { break };
                dst_rows = rest;
                for (dst, src) in dst_row.iter_mut().zip(src_row.iter()) {
                    *dst = *src;
                }
            }
        }
    }
}

/// The joint basis one axis at a time (tables of every order, 2 × 64 codes): each axis's factors
/// multiplied into every row before the next axis.
#[inline(never)]
fn joint_basis_axes<const HESSIAN: bool, A: AxisKernel>(
    n: usize,
    axes: &[A],
    codes: &[u8],
    orders: &[u8; NJ],
    x: &[f64],
    rows: &mut [Real],
) {
    const CODES: usize = 2 * ORDERS;
    let row_len = joint_row_len(n);
    if n == 0 {
        return;
    }
    // Per code: F, F', F'' of the current axis. One set of tables for every axis: a code of axis d
    // is at most 2 order_d + 1, and those entries are written for axis d before its rows.
    let (mut f0s, mut f1s, mut f2s) = ([0.0 as Real; CODES], [0.0 as Real; CODES], [0.0 as Real; CODES]);
    for (d, ((axis, &xd), &order)) in axes.iter().zip(x.iter()).zip(orders.iter()).enumerate().take(n) {
        axis_factors::<HESSIAN, CODES, A>(axis, xd, (order as usize).min(ORDERS - 1), &mut f0s, &mut f1s, &mut f2s);
        let mut code_rows = codes;
        for row in rows.chunks_exact_mut(row_len.max(1)) {
            let Some((code_row, rest)) = code_rows.split_at_checked(n) else { break };
            code_rows = rest;
            // Codes are below CODES: the remainder only spares the bounds checks.
            let code = code_row.get(d).copied().unwrap_or(0) as usize % CODES;
            let at = |t: &[Real; CODES]| t.get(code).copied().unwrap_or(0.0);
            let f = [at(&f0s), at(&f1s), if HESSIAN { at(&f2s) } else { 0.0 }];
            let Some((phi, rest)) = row.split_first_mut() else { continue };
            let Some((grad, hess)) = rest.split_at_mut_checked(n) else { continue };
            multiply_factor::<HESSIAN>(phi, grad, hess, n, d, f);
        }
    }
}

/// The task basis at y (internal units, m coordinates) — calls `each(g, ψ_g, ∇ψ_g, ∇²ψ_g)` for g = 0..r_W in order (no storage needed); with `hessian == false` the Hessian argument is zeros.
///
/// r_W = `exponents.len() / m`, exponents ≤ MAX_EXPANSION_ORDER (as validated). Computed in
/// [`Real`]: per coordinate one exp and the power recurrence, every exponent's factors F, F'/a,
/// F''/a² once (tables of 16 or, for higher exponents, 64 per coordinate on the stack), then per
/// function the product of its m factors.
#[inline(always)]
pub fn for_each_task_basis(
    task_kernel: &TaskKernel,
    exponents: &[u8],
    m: usize,
    y: &[Real],
    hessian: bool,
    each: impl FnMut(usize, Real, &[Real; MT], &[[Real; MT]; MT]),
) {
    for_each_task_basis_with_orders(task_kernel, exponents, &task_orders(exponents, m), m, y, hessian, each)
}

/// [`for_each_task_basis`] (bit-identical) with the coordinates' highest exponents given
/// ([`task_orders`] of `exponents`, computed once per model).
#[inline(always)]
pub fn for_each_task_basis_with_orders(
    task_kernel: &TaskKernel,
    exponents: &[u8],
    orders: &[u8; MT],
    m: usize,
    y: &[Real],
    hessian: bool,
    each: impl FnMut(usize, Real, &[Real; MT], &[[Real; MT]; MT]),
) {
    // Inlined, so constant flags pick one instance: their branches stay out of the per-function loop.
    let small = (orders.iter().copied().max().unwrap_or(0) as usize) < SMALL_ORDERS;
    match (hessian, small) {
        (true, true) => task_basis::<true, SMALL_ORDERS>(task_kernel, exponents, orders, m, y, each),
        (true, false) => task_basis::<true, ORDERS>(task_kernel, exponents, orders, m, y, each),
        (false, true) => task_basis::<false, SMALL_ORDERS>(task_kernel, exponents, orders, m, y, each),
        (false, false) => task_basis::<false, ORDERS>(task_kernel, exponents, orders, m, y, each),
    }
}

/// [`for_each_task_basis_with_orders`] with the Hessian switch at compile time and tables of `K`
/// exponents (every exponent below it).
#[inline(always)]
fn task_basis<const HESSIAN: bool, const K: usize>(
    task_kernel: &TaskKernel,
    exponents: &[u8],
    orders: &[u8; MT],
    m: usize,
    y: &[Real],
    mut each: impl FnMut(usize, Real, &[Real; MT], &[[Real; MT]; MT]),
) {
    if m == 0 || m > MT {
        return;
    }
    let inv_a = 1.0 / task_kernel.width as Real;
    let inv_a2 = inv_a * inv_a;
    // Per coordinate and exponent: F, F'/a, F''/a².
    let (mut f0s, mut f1s, mut f2s) = ([[0.0 as Real; K]; MT], [[0.0 as Real; K]; MT], [[0.0 as Real; K]; MT]);
    let tables = f0s.iter_mut().zip(f1s.iter_mut()).zip(f2s.iter_mut());
    for (((t0, t1), t2), (y_c, &order)) in tables.zip(y.iter().zip(orders.iter())).take(m) {
        let u_c = *y_c * inv_a;
        hermite_factors(u_c, (order as usize).min(K - 1), |k, f0, f1, f2| {
            if let (Some(d0), Some(d1), Some(d2)) = (t0.get_mut(k), t1.get_mut(k), t2.get_mut(k)) {
                (*d0, *d1) = (f0, f1 * inv_a);
                if HESSIAN {
                    *d2 = f2 * inv_a2;
                }
            }
        });
    }
    let mut hess_rows = [[0.0 as Real; MT]; MT];
    for (g, alpha) in exponents.chunks_exact(m.max(1)).enumerate() {
        let (mut psi, mut grad, mut hess) = (1.0 as Real, [0.0 as Real; MT], [0.0 as Real; MT * MT]);
        for (c, (a, ((t0, t1), t2))) in alpha.iter().zip(f0s.iter().zip(f1s.iter()).zip(f2s.iter())).enumerate() {
            // Exponents are below K: the remainder only spares the bounds checks.
            let k = *a as usize % K;
            let at = |t: &[Real; K]| t.get(k).copied().unwrap_or(0.0);
            let f = [at(t0), at(t1), if HESSIAN { at(t2) } else { 0.0 }];
            multiply_factor::<HESSIAN>(&mut psi, &mut grad, &mut hess, m, c, f);
        }
        if HESSIAN {
            for (dst, src) in hess_rows.iter_mut().zip(hess.chunks_exact(m.max(1))) {
                for (d, s) in dst.iter_mut().zip(src.iter()) {
                    *d = *s;
                }
            }
        }
        each(g, psi, &grad, &hess_rows);
    }
}

// Checks against f64 references (correctly rounded tables, libm formulas) to f64 tolerances: the f32
// build's accuracy is the firmware's f32 rows (BENCHMARKS "Firmware (QEMU)").
#[cfg(all(test, not(feature = "f32")))]
mod tests;

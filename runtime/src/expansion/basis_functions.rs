//! The basis functions of the fields' expansions (format 5, docs/DESIGN.md §11): the joint basis
//! φ_f(x) = Π_d F_d(x_d) (periodic axes cos(h x)/sin(h x), Gaussian axes the Hermite functions
//! e^{−u²/2} u^k/√(k!), u = x/ℓ) and the task basis ψ_g(y) = Π_c e^{−u_c²/2} u_c^{α_c}/√(α_c!), u = y/a,
//! with their gradients and Hessians. The trainer builds its design matrices with these same
//! functions, so trainer and runtime use the same bits.

use core::ops::{Add, Mul, Neg, Sub};

use crate::flow::Shape;
use crate::real::Real;
use cbd_protocol::{code_order, JointKernel, JointKernelAxis, TaskKernel, MAX_EXPANSION_ORDER, MAX_JOINTS as NJ, MAX_TASK_DIM as MT};

/// Entries of a per-axis table: orders 0..=MAX_EXPANSION_ORDER.
const ORDERS: usize = MAX_EXPANSION_ORDER as usize + 1;

/// √k, k = 0..=63, correctly rounded.
const SQRT: [f64; ORDERS] = [
    0.0,
    1.0,
    core::f64::consts::SQRT_2,
    1.7320508075688772,
    2.0,
    2.23606797749979,
    2.449489742783178,
    2.6457513110645907,
    2.8284271247461903,
    3.0,
    3.1622776601683795,
    3.3166247903554,
    3.4641016151377544,
    3.605551275463989,
    3.7416573867739413,
    3.872983346207417,
    4.0,
    4.123105625617661,
    4.242640687119285,
    4.358898943540674,
    4.47213595499958,
    4.58257569495584,
    4.69041575982343,
    4.795831523312719,
    4.898979485566356,
    5.0,
    5.0990195135927845,
    5.196152422706632,
    5.291502622129181,
    5.385164807134504,
    5.477225575051661,
    5.5677643628300215,
    5.656854249492381,
    5.744562646538029,
    5.830951894845301,
    5.916079783099616,
    6.0,
    6.082762530298219,
    6.164414002968976,
    6.244997998398398,
    6.324555320336759,
    6.4031242374328485,
    6.48074069840786,
    6.557438524302,
    6.6332495807108,
    6.708203932499369,
    6.782329983125268,
    6.855654600401044,
    6.928203230275509,
    7.0,
    7.0710678118654755,
    7.14142842854285,
    7.211102550927978,
    7.280109889280518,
    7.3484692283495345,
    7.416198487095663,
    7.483314773547883,
    7.54983443527075,
    7.615773105863909,
    7.681145747868608,
    7.745966692414834,
    7.810249675906654,
    7.874007874011811,
    7.937253933193772,
];
/// 1/√k, k = 1..=63, correctly rounded (entry 0 unused).
const INV_SQRT: [f64; ORDERS] = [
    0.0,
    1.0,
    core::f64::consts::FRAC_1_SQRT_2,
    0.5773502691896257,
    0.5,
    0.4472135954999579,
    0.408248290463863,
    0.37796447300922725,
    0.3535533905932738,
    0.3333333333333333,
    0.31622776601683794,
    0.30151134457776363,
    0.28867513459481287,
    0.2773500981126146,
    0.2672612419124244,
    0.25819888974716115,
    0.25,
    0.24253562503633297,
    0.23570226039551584,
    0.22941573387056177,
    0.22360679774997896,
    0.2182178902359924,
    0.21320071635561044,
    0.20851441405707477,
    0.2041241452319315,
    0.2,
    0.19611613513818404,
    0.19245008972987526,
    0.18898223650461363,
    0.18569533817705186,
    0.18257418583505536,
    0.1796053020267749,
    0.1767766952966369,
    0.17407765595569785,
    0.17149858514250885,
    0.1690308509457033,
    0.16666666666666666,
    0.1643989873053573,
    0.16222142113076254,
    0.16012815380508713,
    0.15811388300841897,
    0.15617376188860607,
    0.1543033499620919,
    0.15249857033260467,
    0.15075567228888181,
    0.14907119849998599,
    0.14744195615489714,
    0.14586499149789456,
    0.14433756729740643,
    0.14285714285714285,
    0.1414213562373095,
    0.14002800840280097,
    0.1386750490563073,
    0.13736056394868904,
    0.13608276348795434,
    0.13483997249264842,
    0.1336306209562122,
    0.13245323570650439,
    0.13130643285972254,
    0.13018891098082386,
    0.12909944487358058,
    0.12803687993289598,
    0.1270001270001905,
    0.12598815766974242,
];

/// Values per joint-basis row: φ, ∇φ (n), ∇²φ (n×n) — the layout of the query's kernel rows.
pub const fn joint_row_len(n: usize) -> usize {
    1 + n + n * n
}

/// The scalars the basis is computed in: f64 for the joint features (rounded once to [`Real`]),
/// [`Real`] for the task basis at the flow's state.
pub(crate) trait Scalar: Copy + Add<Output = Self> + Sub<Output = Self> + Mul<Output = Self> + Neg<Output = Self> {
    const ZERO: Self;
    const ONE: Self;
    fn of(x: f64) -> Self;
    fn exp(self) -> Self;
}

impl Scalar for f64 {
    const ZERO: f64 = 0.0;
    const ONE: f64 = 1.0;
    #[inline(always)]
    fn of(x: f64) -> f64 {
        x
    }
    #[inline(always)]
    fn exp(self) -> f64 {
        crate::real::exp_f64(self)
    }
}

impl Scalar for f32 {
    const ZERO: f32 = 0.0;
    const ONE: f32 = 1.0;
    #[inline(always)]
    fn of(x: f64) -> f32 {
        x as f32
    }
    #[inline(always)]
    fn exp(self) -> f32 {
        libm::expf(self)
    }
}

/// The Hermite functions q_k = e^{−u²/2} u^k/√(k!), k = 0, 1, …, by their recurrence q_0 = e^{−u²/2},
/// q_k = q_{k−1} u/√k (no overflow: every q_k is the function's own value, at most about 1), with
/// each one's factor F = q_k and its first two derivatives in u,
/// F' = √k q_{k−1} − u q_k, F'' = √k √(k−1) q_{k−2} − 2u √k q_{k−1} + (u² − 1) q_k:
/// `each(k, F, F', F'')` for k = 0..=order.
#[inline(always)]
fn hermite_factors<T: Scalar>(u: T, order: usize, mut each: impl FnMut(usize, T, T, T)) {
    let sqrt = |i: usize| T::of(SQRT.get(i).copied().unwrap_or(0.0));
    // q_k, q_{k−1}, q_{k−2} (zero below q_0).
    let (mut q0, mut q1, mut q2) = ((T::of(-0.5) * u * u).exp(), T::ZERO, T::ZERO);
    for k in 0..=order.min(MAX_EXPANSION_ORDER as usize) {
        if k > 0 {
            (q2, q1) = (q1, q0);
            q0 = q0 * u * T::of(INV_SQRT.get(k).copied().unwrap_or(0.0));
        }
        let raised = sqrt(k) * q1;
        let first = raised - u * q0;
        let second = sqrt(k) * sqrt(k.saturating_sub(1)) * q2 - T::of(2.0) * u * raised + (u * u - T::ONE) * q0;
        each(k, q0, first, second);
    }
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
    // One instance per case: the flags' branches stay out of the per-row loop. Orders below
    // SMALL_ORDERS (the common case): every axis's tables at once, each row formed in registers,
    // for two and six joints with n known at compile time; higher orders: one axis at a time.
    let small = (orders.iter().copied().max().unwrap_or(0) as usize) < SMALL_ORDERS;
    let n = shape.n();
    match (hessian, small, n) {
        (true, true, 2) => joint_basis_rows::<true, 2, true>(2, joint_kernel, codes, orders, x, rows),
        (true, true, 6) => joint_basis_rows::<true, 6, true>(6, joint_kernel, codes, orders, x, rows),
        (true, true, _) => joint_basis_rows::<true, NJ, false>(n, joint_kernel, codes, orders, x, rows),
        (false, true, 2) => joint_basis_rows::<false, 2, true>(2, joint_kernel, codes, orders, x, rows),
        (false, true, 6) => joint_basis_rows::<false, 6, true>(6, joint_kernel, codes, orders, x, rows),
        (false, true, _) => joint_basis_rows::<false, NJ, false>(n, joint_kernel, codes, orders, x, rows),
        (true, false, _) => joint_basis_axes::<true>(n, joint_kernel, codes, orders, x, rows),
        (false, false, _) => joint_basis_axes::<false>(n, joint_kernel, codes, orders, x, rows),
    }
}

/// Codes `h << 1 | s` of orders below SMALL_ORDERS.
const SMALL_CODES: usize = 2 * SMALL_ORDERS;

/// The factors F, F', F'' (HESSIAN) of every code of one axis up to `order` (≤ CODES/2 − 1) at x_d,
/// computed in f64 and rounded once to [`Real`]; entries above are left as they are.
#[inline(always)]
fn axis_factors<const HESSIAN: bool, const CODES: usize>(
    axis: &JointKernelAxis,
    xd: f64,
    order: usize,
    f0s: &mut [Real; CODES],
    f1s: &mut [Real; CODES],
    f2s: &mut [Real; CODES],
) {
    let mut set = |code: usize, f0: f64, f1: f64, f2: f64| {
        if let (Some(d0), Some(d1), Some(d2)) = (f0s.get_mut(code), f1s.get_mut(code), f2s.get_mut(code)) {
            (*d0, *d1) = (f0 as Real, f1 as Real);
            if HESSIAN {
                *d2 = f2 as Real;
            }
        }
    };
    match *axis {
        // cos hx: (cos, −h sin, −h² cos); sin hx: (sin, h cos, −h² sin), harmonics by
        // cos((h+1)x) = cos hx cos x − sin hx sin x, sin((h+1)x) = sin hx cos x + cos hx sin x.
        JointKernelAxis::Periodic { .. } => {
            let (s1, c1) = libm::sincos(xd);
            let (mut c, mut s) = (1.0, 0.0);
            for k in 0..=order {
                let h = k as f64;
                set(2 * k, c, -h * s, -(h * h) * c);
                set(2 * k + 1, s, h * c, -(h * h) * s);
                (c, s) = (c * c1 - s * s1, s * c1 + c * s1);
            }
        }
        // The Hermite function of u = x/ℓ; its derivatives in x are those in u over ℓ, ℓ².
        // (Gaussian codes have no sine bit; both entries hold the factor, as the order does.)
        JointKernelAxis::Gaussian { width } => {
            let u = xd / width;
            let inv_width = 1.0 / width;
            hermite_factors(u, order, |k, f0, f1, f2| {
                let (f1, f2) = (f1 * inv_width, f2 * (inv_width * inv_width));
                set(2 * k, f0, f1, f2);
                set(2 * k + 1, f0, f1, f2);
            });
        }
    }
}

/// The joint basis with every axis's factor tables at once (orders below SMALL_ORDERS): each row's
/// product, gradient and (HESSIAN) Hessian formed axis by axis in registers, then written once.
/// `EXACT`: n is AXES (loops unrolled); otherwise n ≤ AXES at run time.
#[inline(never)]
fn joint_basis_rows<const HESSIAN: bool, const AXES: usize, const EXACT: bool>(
    n: usize,
    joint_kernel: &JointKernel,
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
    for (((axis, &xd), &order), ((t0, t1), t2)) in joint_kernel.axes.iter().zip(x.iter()).zip(orders.iter()).zip(tables).take(n) {
        axis_factors::<HESSIAN, SMALL_CODES>(axis, xd, (order as usize).min(SMALL_ORDERS - 1), t0, t1, t2);
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
fn joint_basis_axes<const HESSIAN: bool>(
    n: usize,
    joint_kernel: &JointKernel,
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
    for (d, ((axis, &xd), &order)) in joint_kernel.axes.iter().zip(x.iter()).zip(orders.iter()).enumerate().take(n) {
        axis_factors::<HESSIAN, CODES>(axis, xd, (order as usize).min(ORDERS - 1), &mut f0s, &mut f1s, &mut f2s);
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

#[cfg(test)]
mod tests;

//! The basis functions of the fields' expansions (format 5, docs/DESIGN.md §11): the joint basis
//! φ_f(x) = Π_d F_d(x_d) (periodic axes cos(h x)/sin(h x), Gaussian axes the Hermite functions
//! e^{−u²/2} u^k/√(k!), u = x/ℓ) and the task basis ψ_g(y) = Π_c e^{−u_c²/2} u_c^{α_c}/√(α_c!), u = y/a,
//! with their gradients and Hessians. The trainer builds its design matrices with these same
//! functions, so trainer and runtime use the same bits.

use core::ops::{Add, Mul, Neg, Sub};

use crate::real::Real;
use cbd_protocol::{code_is_sin, code_order, JointKernel, JointKernelAxis, TaskKernel, MAX_EXPANSION_ORDER, MAX_TASK_DIM as MT};

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

/// q_k = e^{−u²/2} u^k/√(k!) for k = 0..=order: q_0 = e^{−u²/2}, q_k = q_{k−1} u/√k (no overflow:
/// every q_k is the function's own value, at most about 1).
#[inline]
fn hermite_table<T: Scalar>(u: T, order: usize, q: &mut [T; ORDERS]) {
    let mut prev = (T::of(-0.5) * u * u).exp();
    for (k, (dst, inv_sqrt)) in q.iter_mut().zip(INV_SQRT.iter()).enumerate().take(order + 1) {
        if k > 0 {
            prev = prev * u * T::of(*inv_sqrt);
        }
        *dst = prev;
    }
}

/// F = e^{−u²/2} u^k/√(k!) and its first two derivatives in u from the [`hermite_table`]:
/// F' = √k q_{k−1} − u q_k, F'' = √k √(k−1) q_{k−2} − 2u √k q_{k−1} + (u² − 1) q_k.
#[inline]
fn hermite_factor<T: Scalar>(q: &[T; ORDERS], k: usize, u: T) -> (T, T, T) {
    let at = |i: Option<usize>| i.and_then(|i| q.get(i)).copied().unwrap_or(T::ZERO);
    let sqrt = |i: usize| T::of(SQRT.get(i).copied().unwrap_or(0.0));
    let (q0, q1, q2) = (at(Some(k)), at(k.checked_sub(1)), at(k.checked_sub(2)));
    let raised = sqrt(k) * q1;
    let first = raised - u * q0;
    let second = sqrt(k) * sqrt(k.saturating_sub(1)) * q2 - T::of(2.0) * u * raised + (u * u - T::ONE) * q0;
    (q0, first, second)
}

/// Multiplies factor d of a product basis function into its running value, gradient and (with
/// `hess`, row-major n×n) Hessian: the product rule, axis by axis. Before the call the entries of
/// axes below d hold the product of factors 0..d; after it those of axes up to d.
#[inline(always)]
fn multiply_factor(phi: &mut Real, grad: &mut [Real], hess: Option<&mut [Real]>, n: usize, d: usize, f: [Real; 3]) {
    let [f0, f1, f2] = f;
    let p = *phi;
    if let Some(hess) = hess {
        // ∂_e ∂_e' (φ F) = F ∂_e ∂_e' φ (e, e' < d); ∂_e ∂_d = F' ∂_e φ; ∂_d ∂_d = F'' φ.
        for (e, h_row) in hess.chunks_exact_mut(n.max(1)).enumerate().take(d + 1) {
            let g_e = grad.get(e).copied().unwrap_or(0.0);
            for (e2, h) in h_row.iter_mut().enumerate().take(d + 1) {
                *h = match (e == d, e2 == d) {
                    (false, false) => *h * f0,
                    (false, true) => g_e * f1,
                    (true, false) => grad.get(e2).copied().unwrap_or(0.0) * f1,
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

/// The largest order the codes of axis `d` use (rows of `n` codes).
fn axis_order(orders: impl Iterator<Item = u8>) -> usize {
    orders.max().map_or(0, |o| o.min(MAX_EXPANSION_ORDER)) as usize
}

/// Every joint basis function at x (f64 joint values, rounded once to Real as kernel::joint_features does): rows of joint_row_len(n) values, r_V rows; with `hessian == false` the ∇² part is left untouched (may be garbage/zero).
/// Harmonics by recurrence from (cos x_d, sin x_d) computed in f64 (no sin/cos per term); Gaussian axes by the power recurrence.
///
/// r_V = `codes.len() / n`; rows beyond `rows.len() / joint_row_len(n)` are not written. Each factor
/// F, F', F'' is computed in f64 and rounded once; the products are formed axis by axis in [`Real`]
/// (one table of 2 × 64 f64 on the stack at a time).
pub fn write_joint_basis(joint_kernel: &JointKernel, codes: &[u8], n: usize, x: &[f64], rows: &mut [Real], hessian: bool) {
    // One instance per case: the flag's branch stays out of the per-row loop.
    if hessian {
        joint_basis::<true>(joint_kernel, codes, n, x, rows)
    } else {
        joint_basis::<false>(joint_kernel, codes, n, x, rows)
    }
}

/// [`write_joint_basis`] with the Hessian switch at compile time.
fn joint_basis<const HESSIAN: bool>(joint_kernel: &JointKernel, codes: &[u8], n: usize, x: &[f64], rows: &mut [Real]) {
    let hessian = HESSIAN;
    let row_len = joint_row_len(n);
    if n == 0 {
        return;
    }
    for row in rows.chunks_exact_mut(row_len.max(1)) {
        if let Some(phi) = row.first_mut() {
            *phi = 1.0;
        }
    }
    for (d, (axis, &xd)) in joint_kernel.axes.iter().zip(x.iter()).enumerate().take(n) {
        let order = axis_order(codes.chunks_exact(n.max(1)).filter_map(|c| c.get(d)).map(|&c| code_order(c)));
        let (mut cos, mut sin) = ([0.0f64; ORDERS], [0.0f64; ORDERS]);
        let (u, inv_width) = match *axis {
            JointKernelAxis::Periodic { .. } => {
                // cos((h+1)x) = cos hx cos x − sin hx sin x, sin((h+1)x) = sin hx cos x + cos hx sin x.
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
        // Rows and codes walked by splitting (a zip of two `chunks_exact` keeps a division-by-zero
        // panic path the optimiser cannot remove).
        let mut code_rows = codes;
        for row in rows.chunks_exact_mut(row_len.max(1)) {
            let Some((code_row, rest)) = code_rows.split_at_checked(n) else { break };
            code_rows = rest;
            let code = code_row.get(d).copied().unwrap_or(0);
            let k = code_order(code) as usize;
            let (f0, f1, f2) = match *axis {
                // cos hx: (cos, −h sin, −h² cos); sin hx: (sin, h cos, −h² sin).
                JointKernelAxis::Periodic { .. } => {
                    let h = k as f64;
                    let (c, s) = (cos.get(k).copied().unwrap_or(0.0), sin.get(k).copied().unwrap_or(0.0));
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
            let Some((phi, rest)) = row.split_first_mut() else { continue };
            let Some((grad, hess)) = rest.split_at_mut_checked(n) else { continue };
            multiply_factor(phi, grad, if hessian { Some(hess) } else { None }, n, d, [f0 as Real, f1 as Real, f2 as Real]);
        }
    }
}

/// The task basis at y (internal units, m coordinates) — calls `each(g, ψ_g, ∇ψ_g, ∇²ψ_g)` for g = 0..r_W in order (no storage needed); with `hessian == false` the Hessian argument is zeros.
///
/// r_W = `exponents.len() / m`. Computed in [`Real`]: per coordinate one exp and the power
/// recurrence (one table of 64 values per coordinate on the stack), then per function the product
/// of its m factors.
#[inline(always)]
pub fn for_each_task_basis(
    task_kernel: &TaskKernel,
    exponents: &[u8],
    m: usize,
    y: &[Real],
    hessian: bool,
    each: impl FnMut(usize, Real, &[Real; MT], &[[Real; MT]; MT]),
) {
    // Inlined, so a constant flag picks one instance: its branch stays out of the per-function loop.
    if hessian {
        task_basis::<true>(task_kernel, exponents, m, y, each)
    } else {
        task_basis::<false>(task_kernel, exponents, m, y, each)
    }
}

/// [`for_each_task_basis`] with the Hessian switch at compile time.
#[inline(always)]
fn task_basis<const HESSIAN: bool>(
    task_kernel: &TaskKernel,
    exponents: &[u8],
    m: usize,
    y: &[Real],
    mut each: impl FnMut(usize, Real, &[Real; MT], &[[Real; MT]; MT]),
) {
    let hessian = HESSIAN;
    if m == 0 || m > MT {
        return;
    }
    let inv_a = 1.0 / task_kernel.width as Real;
    let mut u = [0.0 as Real; MT];
    let mut tables = [[0.0 as Real; ORDERS]; MT];
    for (c, ((u_c, table), y_c)) in u.iter_mut().zip(tables.iter_mut()).zip(y.iter()).enumerate().take(m) {
        *u_c = *y_c * inv_a;
        let order = axis_order(exponents.chunks_exact(m.max(1)).filter_map(|e| e.get(c)).copied());
        hermite_table(*u_c, order, table);
    }
    let inv_a2 = inv_a * inv_a;
    let mut hess_rows = [[0.0 as Real; MT]; MT];
    for (g, alpha) in exponents.chunks_exact(m.max(1)).enumerate() {
        let (mut psi, mut grad, mut hess) = (1.0 as Real, [0.0 as Real; MT], [0.0 as Real; MT * MT]);
        for (c, ((a, table), u_c)) in alpha.iter().zip(tables.iter()).zip(u.iter()).enumerate() {
            let (f0, f1, f2) = hermite_factor(table, *a as usize, *u_c);
            let hess = if hessian { Some(hess.as_mut_slice()) } else { None };
            multiply_factor(&mut psi, &mut grad, hess, m, c, [f0, f1 * inv_a, f2 * inv_a2]);
        }
        if hessian {
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

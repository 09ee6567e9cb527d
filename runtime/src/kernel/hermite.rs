//! The Hermite functions e^{−u²/2} u^k/√(k!) with their first two derivatives, by recurrence: the
//! factors of a Gaussian joint axis's own basis ([`super::axis`]) and of the task basis
//! (`crate::expansion`), one implementation in the scalar each computes in.

use core::ops::{Add, Mul, Neg, Sub};

use cbd_protocol::MAX_EXPANSION_ORDER;

/// Entries of a per-axis table: orders 0..=MAX_EXPANSION_ORDER.
pub(crate) const ORDERS: usize = MAX_EXPANSION_ORDER as usize + 1;

/// √k, k = 0..=63, correctly rounded.
pub(crate) const SQRT: [f64; ORDERS] = [
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
pub(crate) const INV_SQRT: [f64; ORDERS] = [
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

/// The scalars the basis is computed in: f64 for the joint features (rounded once to `Real`),
/// `Real` for the task basis at the flow's state.
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
pub(crate) fn hermite_factors<T: Scalar>(u: T, order: usize, mut each: impl FnMut(usize, T, T, T)) {
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

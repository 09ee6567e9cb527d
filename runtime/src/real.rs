//! The evaluation scalar: `f64`, or `f32` with the crate feature `f32` (for single-precision FPUs
//! such as the Cortex-M4's). Blobs keep f64; the nominal model and the query's kernel features
//! are computed in f64 and rounded once. Never enable `f32` in a build that contains the trainer
//! (cargo unifies features): build it with `-p` selections or in `examples/firmware` only.

/// The scalar of the flows, the storage and the integration.
#[cfg(not(feature = "f32"))]
pub type Real = f64;
/// The scalar of the flows, the storage and the integration.
#[cfg(feature = "f32")]
pub type Real = f32;

/// e^x in [`Real`]: [`exp_f64`] in the f64 build, libm's `expf` in the f32 build.
#[inline(always)]
pub fn exp(x: Real) -> Real {
    #[cfg(not(feature = "f32"))]
    {
        exp_f64(x)
    }
    #[cfg(feature = "f32")]
    {
        libm::expf(x)
    }
}

/// 2^(j/32), j = 0..31, correctly rounded.
const EXP2_FRACTIONS: [f64; 32] = [
    f64::from_bits(0x3ff0000000000000),
    f64::from_bits(0x3ff059b0d3158574),
    f64::from_bits(0x3ff0b5586cf9890f),
    f64::from_bits(0x3ff11301d0125b51),
    f64::from_bits(0x3ff172b83c7d517b),
    f64::from_bits(0x3ff1d4873168b9aa),
    f64::from_bits(0x3ff2387a6e756238),
    f64::from_bits(0x3ff29e9df51fdee1),
    f64::from_bits(0x3ff306fe0a31b715),
    f64::from_bits(0x3ff371a7373aa9cb),
    f64::from_bits(0x3ff3dea64c123422),
    f64::from_bits(0x3ff44e086061892d),
    f64::from_bits(0x3ff4bfdad5362a27),
    f64::from_bits(0x3ff5342b569d4f82),
    f64::from_bits(0x3ff5ab07dd485429),
    f64::from_bits(0x3ff6247eb03a5585),
    f64::from_bits(0x3ff6a09e667f3bcd),
    f64::from_bits(0x3ff71f75e8ec5f74),
    f64::from_bits(0x3ff7a11473eb0187),
    f64::from_bits(0x3ff82589994cce13),
    f64::from_bits(0x3ff8ace5422aa0db),
    f64::from_bits(0x3ff93737b0cdc5e5),
    f64::from_bits(0x3ff9c49182a3f090),
    f64::from_bits(0x3ffa5503b23e255d),
    f64::from_bits(0x3ffae89f995ad3ad),
    f64::from_bits(0x3ffb7f76f2fb5e47),
    f64::from_bits(0x3ffc199bdd85529c),
    f64::from_bits(0x3ffcb720dcef9069),
    f64::from_bits(0x3ffd5818dcfba487),
    f64::from_bits(0x3ffdfc97337b9b5f),
    f64::from_bits(0x3ffea4afa2a490da),
    f64::from_bits(0x3fff50765b6e4540),
];
/// 32/ln 2.
const INV_LN2_32: f64 = f64::from_bits(0x4047_1547_652b_82fe);
/// ln 2/32 in two parts: `HI` has 32 significant bits, so k·HI is exact for |k| < 2^21.
const LN2_32_HI: f64 = f64::from_bits(0x3f96_2e42_fee0_0000);
const LN2_32_LO: f64 = f64::from_bits(0x3d9a_39ef_3579_3c76);
/// 1.5·2^52: adding it rounds a value below 2^51 to an integer, which its low bits then hold.
const ROUND_SHIFT: f64 = 6_755_399_441_055_744.0;

/// e^x for f64, within about 1 ulp of the true value, in ~35 basic IEEE operations and no division
/// (libm's `exp` costs about twice that): every step is an exactly specified IEEE operation, so
/// results are bit-identical on every target. Tang's method: e^x = 2^(k/32) e^r with
/// k = round(32x/ln 2), r = x − k ln2/32 (|r| ≤ ln2/64), e^r − 1 by its Taylor polynomial to r^6
/// (truncation below 4e-18), 2^(j/32) from a table and 2^(k div 32) built from its bits.
#[inline]
pub fn exp_f64(x: f64) -> f64 {
    if x.is_nan() {
        return x;
    }
    if x > 709.782_712_893_384 {
        return f64::INFINITY;
    }
    if x < -745.133_219_101_941_2 {
        return 0.0;
    }
    let shifted = x * INV_LN2_32 + ROUND_SHIFT;
    let k = (shifted.to_bits() as i64).wrapping_sub(ROUND_SHIFT.to_bits() as i64);
    let kf = shifted - ROUND_SHIFT;
    let r = (x - kf * LN2_32_HI) - kf * LN2_32_LO;
    let p = r + r * r * (0.5 + r * (1.0 / 6.0 + r * (1.0 / 24.0 + r * (1.0 / 120.0 + r * (1.0 / 720.0)))));
    let t = EXP2_FRACTIONS.get((k & 31) as usize).copied().unwrap_or(1.0);
    let y = t + t * p;
    // 2^(k div 32) in two factors, so that results near overflow or in the subnormal range scale right.
    let e = k >> 5;
    let (e1, e2) = (e >> 1, e - (e >> 1));
    y * pow2(e1) * pow2(e2)
}

/// 2^e for −1022 ≤ e ≤ 1023.
#[inline(always)]
fn pow2(e: i64) -> f64 {
    f64::from_bits(((e + 1023) as u64) << 52)
}

/// A [`Real`] widened to f64 (exact; the identity in the f64 build).
#[inline(always)]
#[allow(clippy::unnecessary_cast, clippy::useless_conversion)]
pub fn to_f64(x: Real) -> f64 {
    x as f64
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ulps(a: f64, b: f64) -> u64 {
        (a.to_bits() as i64).abs_diff(b.to_bits() as i64)
    }

    #[test]
    fn exp_f64_is_within_one_ulp_of_libm_over_the_whole_range() {
        // (libm's exp is itself within 1 ulp of the true value.)
        let mut worst = 0;
        let mut state = 0x2545_f491_4f6c_dd1du64;
        for i in 0..400_000 {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            let u = (state >> 11) as f64 / (1u64 << 53) as f64;
            // Most of the samples where the flows use exp (−60..0), the rest over the whole range.
            let x = if i % 4 == 0 { -745.0 + u * (709.7 + 745.0) } else { -60.0 * u };
            let (a, b) = (exp_f64(x), libm::exp(x));
            if b > f64::MIN_POSITIVE {
                worst = worst.max(ulps(a, b));
            } else {
                assert!((a - b).abs() <= 2.0 * f64::from_bits(1), "x = {x}: {a} vs {b}");
            }
        }
        assert!(worst <= 1, "worst difference {worst} ulp");
    }

    #[test]
    fn exp_f64_special_values() {
        assert_eq!(exp_f64(0.0), 1.0);
        assert_eq!(exp_f64(-0.0), 1.0);
        assert_eq!(exp_f64(1.0), core::f64::consts::E);
        assert_eq!(exp_f64(f64::NEG_INFINITY), 0.0);
        assert_eq!(exp_f64(f64::INFINITY), f64::INFINITY);
        assert!(exp_f64(f64::NAN).is_nan());
        assert!(exp_f64(709.78).is_finite() && exp_f64(709.79).is_infinite());
        assert!(exp_f64(-745.0) > 0.0 && exp_f64(-746.0) == 0.0);
    }
}

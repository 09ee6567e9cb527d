//! Nested least-squares F-test: does adding regressors to an intercept-only model explain the
//! residual beyond chance? F = ((SSE₀ − SSE₁)/df₁) / (SSE₁/df₂), tail probability
//! P(F ≥ f) = I_{df₂/(df₂+df₁f)}(df₂/2, df₁/2) (regularised incomplete beta).

use faer::{Mat, Side};

/// Residual sum of squares of the least-squares fit of `r` on the columns of `x` and the
/// numerical rank used (pseudo-inverse, directions below 1e-10 λ_max dropped; columns scaled).
pub fn least_squares_sse(x: &Mat<f64>, r: &[f64]) -> (f64, usize) {
    let p = x.ncols();
    let rr: f64 = r.iter().map(|v| v * v).sum();
    if p == 0 {
        return (rr, 0);
    }
    let scale: Vec<f64> = (0..p).map(|k| (0..x.nrows()).map(|i| x[(i, k)].powi(2)).sum::<f64>().sqrt().max(f64::MIN_POSITIVE)).collect();
    let xs = Mat::from_fn(x.nrows(), p, |i, k| x[(i, k)] / scale[k]);
    let g = xs.transpose() * &xs;
    let rv = Mat::from_fn(r.len(), 1, |i, _| r[i]);
    let b = xs.transpose() * &rv;
    let Ok(evd) = g.self_adjoint_eigen(Side::Lower) else { return (rr, 0) };
    let values: Vec<f64> = (0..p).map(|k| evd.S()[k]).collect();
    let lmax = values.iter().cloned().fold(0.0, f64::max);
    let (mut explained, mut rank) = (0.0, 0);
    for (k, &l) in values.iter().enumerate() {
        if l > 1e-10 * lmax && l > 0.0 {
            let c: f64 = (0..p).map(|i| evd.U()[(i, k)] * b[(i, 0)]).sum();
            explained += c * c / l;
            rank += 1;
        }
    }
    ((rr - explained).max(0.0), rank)
}

/// ln Γ(x), x > 0 (Lanczos, g = 7, 9 terms; relative error ~1e-15).
pub(crate) fn ln_gamma(x: f64) -> f64 {
    const C: [f64; 9] = [
        0.999_999_999_999_809_9,
        676.520_368_121_885_1,
        -1_259.139_216_722_402_8,
        771.323_428_777_653_1,
        -176.615_029_162_140_6,
        12.507_343_278_686_905,
        -0.138_571_095_265_720_12,
        9.984_369_578_019_572e-6,
        1.505_632_735_149_311_6e-7,
    ];
    if x < 0.5 {
        return (std::f64::consts::PI / (std::f64::consts::PI * x).sin()).ln() - ln_gamma(1.0 - x);
    }
    let x = x - 1.0;
    let mut a = C[0];
    let t = x + 7.5;
    for (i, c) in C.iter().enumerate().skip(1) {
        a += c / (x + i as f64);
    }
    0.5 * (2.0 * std::f64::consts::PI).ln() + (x + 0.5) * t.ln() - t + a.ln()
}

/// Continued fraction of the incomplete beta (modified Lentz).
fn beta_cf(a: f64, b: f64, x: f64) -> f64 {
    let tiny = 1e-300;
    let (qab, qap, qam) = (a + b, a + 1.0, a - 1.0);
    let mut c = 1.0;
    let mut d = 1.0 - qab * x / qap;
    if d.abs() < tiny {
        d = tiny;
    }
    d = 1.0 / d;
    let mut h = d;
    for m in 1..10_000 {
        let m = m as f64;
        let m2 = 2.0 * m;
        let aa = m * (b - m) * x / ((qam + m2) * (a + m2));
        d = 1.0 + aa * d;
        d = if d.abs() < tiny { tiny } else { d };
        c = 1.0 + aa / c;
        c = if c.abs() < tiny { tiny } else { c };
        d = 1.0 / d;
        h *= d * c;
        let aa = -(a + m) * (qab + m) * x / ((a + m2) * (qap + m2));
        d = 1.0 + aa * d;
        d = if d.abs() < tiny { tiny } else { d };
        c = 1.0 + aa / c;
        c = if c.abs() < tiny { tiny } else { c };
        d = 1.0 / d;
        let del = d * c;
        h *= del;
        if (del - 1.0).abs() < 1e-15 {
            break;
        }
    }
    h
}

/// Regularised incomplete beta I_x(a, b).
pub fn incomplete_beta(a: f64, b: f64, x: f64) -> f64 {
    if x <= 0.0 {
        return 0.0;
    }
    if x >= 1.0 {
        return 1.0;
    }
    let ln_front = ln_gamma(a + b) - ln_gamma(a) - ln_gamma(b) + a * x.ln() + b * (1.0 - x).ln();
    if x < (a + 1.0) / (a + b + 2.0) {
        ln_front.exp() * beta_cf(a, b, x) / a
    } else {
        1.0 - ln_front.exp() * beta_cf(b, a, 1.0 - x) / b
    }
}

/// P(F(df1, df2) ≥ f).
pub fn f_tail(f: f64, df1: f64, df2: f64) -> f64 {
    if f.is_nan() || f <= 0.0 {
        return 1.0;
    }
    incomplete_beta(df2 / 2.0, df1 / 2.0, df2 / (df2 + df1 * f))
}

/// Result of one nested F-test.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FTest {
    pub f: f64,
    pub df1: usize,
    pub df2: usize,
    pub p_value: f64,
    /// (SSE₀ − SSE₁) / SSE₀: the share of the residual the regressors explain.
    pub explained: f64,
}

/// F-test of `null` (columns) against `null ∪ extra` for the response `r`.
pub fn nested_f_test(null: &Mat<f64>, extra: &Mat<f64>, r: &[f64]) -> FTest {
    let (sse0, rank0) = least_squares_sse(null, r);
    let both =
        Mat::from_fn(
            r.len(),
            null.ncols() + extra.ncols(),
            |i, k| if k < null.ncols() { null[(i, k)] } else { extra[(i, k - null.ncols())] },
        );
    let (sse1, rank1) = least_squares_sse(&both, r);
    let df1 = rank1.saturating_sub(rank0);
    let df2 = r.len().saturating_sub(rank1);
    let explained = if sse0 > 0.0 { ((sse0 - sse1) / sse0).max(0.0) } else { 0.0 };
    if df1 == 0 || df2 == 0 || sse1 <= 0.0 {
        let p = if sse0 > sse1 && df1 > 0 { 0.0 } else { 1.0 };
        return FTest { f: if p == 0.0 { f64::INFINITY } else { 0.0 }, df1, df2, p_value: p, explained };
    }
    let f = ((sse0 - sse1).max(0.0) / df1 as f64) / (sse1 / df2 as f64);
    FTest { f, df1, df2, p_value: f_tail(f, df1 as f64, df2 as f64), explained }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn f_tail_matches_known_values() {
        // F(1, ν) = t(ν)²: P(|t_10| ≥ 2.228) = 0.05; F(2, ∞-like) ≈ exp(−f) for χ²₂/2.
        assert!((f_tail(2.228_138_851_964_938f64.powi(2), 1.0, 10.0) - 0.05).abs() < 1e-9);
        assert!((f_tail(3.0, 2.0, 1e7) - (-3.0f64).exp()).abs() < 1e-5);
        // Tables: F(5, 20) 0.01 point 4.1027.
        assert!((f_tail(4.1027, 5.0, 20.0) - 0.01).abs() < 1e-4);
        assert!((ln_gamma(5.0) - 24f64.ln()).abs() < 1e-13);
    }

    #[test]
    fn detects_a_sine_and_not_noise() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(2);
        let n = 500;
        let q: Vec<f64> = (0..n).map(|_| rng.gen_range(-3.0..3.0)).collect();
        let null = Mat::from_fn(n, 1, |_, _| 1.0);
        let extra = Mat::from_fn(n, 2, |i, k| if k == 0 { (2.0 * q[i]).cos() } else { (2.0 * q[i]).sin() });
        let noise: Vec<f64> = (0..n).map(|_| rng.gen_range(-1.0..1.0)).collect();
        assert!(nested_f_test(&null, &extra, &noise).p_value > 1e-3);
        let signal: Vec<f64> = (0..n).map(|i| noise[i] + 0.3 * (2.0 * q[i]).sin()).collect();
        let t = nested_f_test(&null, &extra, &signal);
        assert!(t.p_value < 1e-6 && t.explained > 0.05, "{t:?}");
    }
}

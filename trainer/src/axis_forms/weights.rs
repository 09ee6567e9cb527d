//! The per-axis weights of the kernels' expansions (docs/DESIGN.md §11): how much of k(x, x) each
//! order carries. Both lists sum to one, so the product over axes of a mode's weights is its share
//! of the kernel's total weight, and truncation can be stated as the share dropped.

/// Above this b [`periodic_weights`] uses the Bessel functions' large-argument form (relative
/// error about 1/(8b) < 2e-9) instead of a recurrence of ~12 √b terms.
const ASYMPTOTIC_B: f64 = 1e8;

/// ω_h = e^{−b} I_h(b) (2 − δ_h0), h = 0..=`max_order`: exp(b (cos Δ − 1)) = Σ_h ω_h cos hΔ, Σ_h ω_h = 1.
/// Miller's backward recurrence I_{k−1} = (2k/b) I_k + I_{k+1}, normalised by e^{−b}(I_0 + 2 Σ I_k) = 1
/// (stable for every b > 0; no overflow: the sequence is rescaled as it grows).
pub fn periodic_weights(b: f64, max_order: usize) -> Vec<f64> {
    assert!(b > 0.0 && b.is_finite(), "periodic kernel b = {b}");
    if b > ASYMPTOTIC_B {
        // The recurrence would start near 12 √b (960 GB of values at b = 1e20: an abort, issue 27).
        // Here e^{−b} I_h(b) = e^{−h²/2b} / √(2πb) (1 + O(1/b)), normalised the same way.
        let v = |h: usize| (-((h * h) as f64) / (2.0 * b)).exp() / (2.0 * std::f64::consts::PI * b).sqrt();
        return (0..=max_order).map(|h| if h == 0 { v(0) } else { 2.0 * v(h) }).collect();
    }
    // Start far enough above both the orders wanted and the bulk of the sequence (I_k decays like e^{−k²/2b}).
    let start = max_order + 40 + (12.0 * b.sqrt()) as usize + (b.min(1e4) as usize / 8);
    let mut values = vec![0.0; start + 2];
    values[start] = 1e-300;
    for k in (1..=start).rev() {
        values[k - 1] = (2.0 * k as f64 / b) * values[k] + values[k + 1];
        if values[k - 1] > 1e250 {
            for v in values[k - 1..].iter_mut() {
                *v *= 1e-250;
            }
        }
    }
    // e^{−b} I_0 + 2 Σ e^{−b} I_k = 1: the normalisation, summed from the smallest terms up.
    let total = values[1..].iter().rev().fold(0.0, |s, v| s + 2.0 * v) + values[0];
    (0..=max_order).map(|h| if h == 0 { values[0] / total } else { 2.0 * values[h] / total }).collect()
}

/// ω_h (as [`periodic_weights`]) and d ln ω_h / d ln b, h = 0..=`max_order`: with v_h = e^{−b} I_h(b),
/// dv_h/db = e^{−b}(I_h' − I_h) and I_h' = (I_{h−1} + I_{h+1})/2 (I_{−1} = I_1), so
/// d ln ω_h / d ln b = b ((v_{h−1} + v_{h+1}) / (2 v_h) − 1); 0 where ω_h underflows (its function carries nothing).
pub fn periodic_weights_and_log_derivatives(b: f64, max_order: usize) -> (Vec<f64>, Vec<f64>) {
    let w = periodic_weights(b, max_order + 1);
    // v_h = e^{−b} I_h: ω_0 = v_0, ω_h = 2 v_h.
    let v = |h: usize| if h == 0 { w[0] } else { 0.5 * w[h] };
    let derivative = (0..=max_order)
        .map(|h| {
            let below = if h == 0 { v(1) } else { v(h - 1) };
            if v(h) > 0.0 {
                b * ((below + v(h + 1)) / (2.0 * v(h)) - 1.0)
            } else {
                0.0
            }
        })
        .collect();
    (w[..=max_order].to_vec(), derivative)
}

/// Poisson(ρ²) probabilities p_k = e^{−ρ²} ρ^{2k} / k!, k = 0..=`max_order`: the share of a Gaussian
/// kernel's expansion, exp(−(x − x')²/2ℓ²) = e^{−x²/2ℓ²} e^{−x'²/2ℓ²} Σ_k (x x'/ℓ²)^k / k!, that
/// order k carries at |x| = ρ ℓ (the diagonal k(x, x) = 1 there); at |x| < ρ ℓ the tail is smaller.
pub fn gaussian_weights(rho: f64, max_order: usize) -> Vec<f64> {
    assert!(rho >= 0.0 && rho.is_finite(), "Gaussian expansion radius {rho}");
    let lambda = rho * rho;
    let mut out = Vec::with_capacity(max_order + 1);
    // In logs: ρ^{2k}/k! overflows long before e^{−ρ²} ρ^{2k}/k! does.
    let mut log_p = -lambda;
    for k in 0..=max_order {
        if k > 0 {
            log_p += if lambda > 0.0 { lambda.ln() } else { f64::NEG_INFINITY } - (k as f64).ln();
        }
        out.push(log_p.exp());
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// e^{−b} I_h(b) by its power series Σ_k (b/2)^{2k+h} / (k! (k+h)!) (small b).
    fn series(b: f64, h: usize) -> f64 {
        let mut term = (b / 2.0).powi(h as i32) / (1..=h).map(|i| i as f64).product::<f64>();
        let mut sum = 0.0;
        for k in 0..60 {
            sum += term;
            term *= (b / 2.0) * (b / 2.0) / ((k + 1) as f64 * (k + 1 + h) as f64);
        }
        (-b).exp() * sum
    }

    /// Issue 27: `--joint-b 1e20` sized the recurrence at 12 √b values (960 GB) and aborted. Above
    /// 1e8 the large-argument form serves, within 1e-5 of the recurrence there (whose own rounding
    /// over its 120 000 steps is about 1e-6).
    #[test]
    fn periodic_weights_of_a_huge_b_are_computed_in_small_memory() {
        let b = ASYMPTOTIC_B;
        let (exact, asymptotic) = (periodic_weights(b * 0.999_999_9, 20), periodic_weights(b * 1.000_000_1, 20));
        for (e, a) in exact.iter().zip(&asymptotic) {
            assert!((e - a).abs() <= 1e-5 * e, "{e} vs {a}");
        }
        let w = periodic_weights(1e300, 20);
        assert!(w.iter().all(|v| v.is_finite() && *v > 0.0) && w.len() == 21, "{w:?}");
    }

    #[test]
    fn periodic_weights_match_the_bessel_series() {
        for b in [1e-5, 0.0037, 0.3, 1.0186, 4.0] {
            let w = periodic_weights(b, 12);
            for (h, wh) in w.iter().enumerate() {
                let want = series(b, h) * if h == 0 { 1.0 } else { 2.0 };
                assert!((wh - want).abs() <= 1e-14 * want.max(1e-300) + 1e-300, "b {b} h {h}: {wh} vs {want}");
            }
        }
    }

    #[test]
    fn periodic_weights_reproduce_the_kernel_and_sum_to_one() {
        for b in [0.01, 1.0186, 30.0, 204.0] {
            let w = periodic_weights(b, 63);
            let total: f64 = w.iter().sum();
            if b < 100.0 {
                assert!((total - 1.0).abs() < 1e-14, "b {b}: sum {total}");
            }
            for delta in [0.0, 0.3, 1.7, 3.1] {
                let series: f64 = w.iter().enumerate().map(|(h, wh)| wh * (h as f64 * delta).cos()).sum();
                let kernel = (b * (f64::cos(delta) - 1.0)).exp();
                let tail = if b < 100.0 { 1e-14 } else { 1.0 - total + 1e-14 };
                assert!((series - kernel).abs() <= tail, "b {b} Δ {delta}: {series} vs {kernel}");
            }
        }
    }

    #[test]
    fn periodic_log_derivatives_match_finite_differences() {
        for b in [1e-4, 0.0037, 0.3, 1.0186, 4.0, 60.0] {
            let (w, d) = periodic_weights_and_log_derivatives(b, 10);
            let h: f64 = 1e-6;
            let (up, down) = (periodic_weights(b * h.exp(), 10), periodic_weights(b * (-h).exp(), 10));
            for k in 0..=10 {
                if w[k] < 1e-250 {
                    continue;
                }
                let fd = (up[k].ln() - down[k].ln()) / (2.0 * h);
                assert!((fd - d[k]).abs() <= 1e-6 * fd.abs().max(1.0), "b {b} h {k}: {} vs {fd}", d[k]);
            }
        }
    }

    #[test]
    fn gaussian_weights_reproduce_the_diagonal() {
        // Σ_k p_k = e^{−ρ²} e^{ρ²} = 1, and the kernel between x = ρℓ and x' = sℓ.
        let rho = 1.7;
        let p = gaussian_weights(rho, 60);
        assert!((p.iter().sum::<f64>() - 1.0).abs() < 1e-14);
        let s = -0.9;
        let series: f64 = (0..=60).map(|k| (rho * s).powi(k) / (1..=k).map(|i| i as f64).product::<f64>()).sum::<f64>()
            * (-(rho * rho + s * s) / 2.0).exp();
        let kernel = (-(rho - s) * (rho - s) / 2.0).exp();
        assert!((series - kernel).abs() < 1e-14);
    }
}

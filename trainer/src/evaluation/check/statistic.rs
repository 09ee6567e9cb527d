//! The check's statistic: the Mahalanobis distance rᵀ C⁻¹ r of the fresh residual against its
//! predictive covariance C, referred to χ²(dof) (docs/DESIGN.md "cbd check"); with a registered
//! frame, the generalised-least-squares residual of r on the frame's tangent T instead:
//! rᵀC⁻¹r − bᵀ(TᵀC⁻¹T)⁻¹b, b = TᵀC⁻¹r, on dof − rank T (Seber & Lee, Linear Regression Analysis,
//! §3.3: the residual sum of squares of a generalised least-squares fit is χ²(n − p) under the model).

use faer::Mat;

/// The statistic, its degrees of freedom and its p-value P(χ²(dof) ≥ statistic).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Statistic {
    pub statistic: f64,
    pub dof: usize,
    pub p_value: f64,
}

/// rᵀC⁻¹r on dim r degrees of freedom, or with `tangent` (T, dim r × k, full column rank) the part
/// of it the columns of T do not explain, on dim r − k. `None` when C (or TᵀC⁻¹T) is not positive
/// definite or nothing is left to test.
pub fn mahalanobis(c: &Mat<f64>, r: &[f64], tangent: Option<&Mat<f64>>) -> Option<Statistic> {
    let dim = r.len();
    let l = super::covariance::cholesky(c.clone())?;
    // w = L⁻¹ r: |w|² = rᵀ C⁻¹ r.
    let mut w = Mat::from_fn(dim, 1, |i, _| r[i]);
    faer::linalg::triangular_solve::solve_lower_triangular_in_place(l.as_ref(), w.as_mut(), crate::numeric::FIXED_SPLIT);
    let mut statistic: f64 = (0..dim).map(|i| w[(i, 0)] * w[(i, 0)]).sum();
    let mut dof = dim;
    if let Some(t) = tangent {
        // U = L⁻¹ T; the part of w in U's span, bᵀ(UᵀU)⁻¹b with b = Uᵀw, is what the frame explains.
        let mut u = t.clone();
        faer::linalg::triangular_solve::solve_lower_triangular_in_place(l.as_ref(), u.as_mut(), crate::numeric::FIXED_SPLIT);
        let (k, par) = (t.ncols(), crate::numeric::FIXED_SPLIT);
        let mut b = Mat::<f64>::zeros(k, 1);
        faer::linalg::matmul::matmul(b.as_mut(), faer::Accum::Replace, u.transpose(), w.as_ref(), 1.0, par);
        let mut utu = Mat::<f64>::zeros(k, k);
        faer::linalg::matmul::matmul(utu.as_mut(), faer::Accum::Replace, u.transpose(), u.as_ref(), 1.0, par);
        // bᵀ (UᵀU)⁻¹ b = |M⁻¹ b|², M the Cholesky factor of UᵀU.
        let m = super::covariance::cholesky(utu)?;
        faer::linalg::triangular_solve::solve_lower_triangular_in_place(m.as_ref(), b.as_mut(), par);
        let explained: f64 = (0..k).map(|i| b[(i, 0)] * b[(i, 0)]).sum();
        statistic = (statistic - explained).max(0.0);
        dof = dim.checked_sub(t.ncols())?;
    }
    (dof > 0 && statistic.is_finite()).then(|| Statistic { statistic, dof, p_value: chi2_survival(statistic, dof as f64) })
}

/// P(χ²(k) ≥ x) = Q(k/2, x/2), the regularised upper incomplete gamma function.
pub fn chi2_survival(x: f64, k: f64) -> f64 {
    if x <= 0.0 {
        return 1.0;
    }
    upper_regularised_gamma(0.5 * k, 0.5 * x)
}

/// Q(a, x) = Γ(a, x)/Γ(a): the series P(a, x) = e⁻ˣ xᵃ/Γ(a) Σ xⁿ/(a (a+1)…(a+n)) below x < a + 1,
/// else Legendre's continued fraction for Γ(a, x) by the modified Lentz method (Numerical Recipes
/// §6.2, `gser` / `gcf`).
fn upper_regularised_gamma(a: f64, x: f64) -> f64 {
    let ln_front = a * x.ln() - x - crate::diagnose::f_test::ln_gamma(a);
    if x < a + 1.0 {
        let (mut term, mut sum, mut ap) = (1.0 / a, 1.0 / a, a);
        for _ in 0..10_000 {
            ap += 1.0;
            term *= x / ap;
            sum += term;
            if term.abs() < sum.abs() * 1e-16 {
                break;
            }
        }
        return (1.0 - sum * ln_front.exp()).clamp(0.0, 1.0);
    }
    let tiny = 1e-300;
    let mut b = x + 1.0 - a;
    let mut c = 1.0 / tiny;
    let mut d = 1.0 / b;
    let mut h = d;
    for i in 1..10_000 {
        let an = -(i as f64) * (i as f64 - a);
        b += 2.0;
        d = an * d + b;
        if d.abs() < tiny {
            d = tiny;
        }
        c = b + an / c;
        if c.abs() < tiny {
            c = tiny;
        }
        d = 1.0 / d;
        let delta = d * c;
        h *= delta;
        if (delta - 1.0).abs() < 1e-16 {
            break;
        }
    }
    (ln_front.exp() * h).clamp(0.0, 1.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Against closed forms and tabulated quantiles: χ²(2) survival is e^(−x/2) exactly; χ²(1) is
    /// erfc(√(x/2)) (3.841459 → 0.05, 6.634897 → 0.01); χ²(10) at 23.209251 → 0.01 and χ²(60) at
    /// 88.379419 → 0.01, 79.081944 → 0.05 (NIST/SEMATECH e-Handbook table 1.3.6.7.4, more digits
    /// from R's qchisq).
    #[test]
    fn chi2_survival_matches_closed_forms_and_tables() {
        for x in [0.1, 1.0, 3.0, 7.5, 30.0, 200.0] {
            let (p, exact) = (chi2_survival(x, 2.0), (-x / 2.0f64).exp());
            assert!((p - exact).abs() <= 1e-12 * exact.max(1e-300), "χ²(2) at {x}: {p} vs {exact}");
        }
        for (x, k, p) in
            [(3.841459, 1.0, 0.05), (6.634897, 1.0, 0.01), (23.209251, 10.0, 0.01), (88.379419, 60.0, 0.01), (79.081944, 60.0, 0.05)]
        {
            let got = chi2_survival(x, k);
            assert!((got - p).abs() <= 2e-6 * p / 0.01, "χ²({k}) at {x}: {got} vs {p}");
        }
        assert_eq!(chi2_survival(0.0, 5.0), 1.0);
        assert!(chi2_survival(1e4, 60.0) < 1e-300 || chi2_survival(1e4, 60.0) == 0.0);
    }

    /// rᵀC⁻¹r against the explicit inverse of a small C, and the frame's part against the residual
    /// of the weighted least-squares fit of r on T done by the normal equations.
    #[test]
    fn the_statistic_is_the_weighted_residual_of_r_on_the_tangent() {
        let c = Mat::from_fn(4, 4, |i, j| if i == j { 2.0 + i as f64 } else { 0.3 / (1.0 + (i as f64 - j as f64).abs()) });
        let r = [0.5, -1.0, 0.25, 2.0];
        let inv = faer::linalg::solvers::DenseSolveCore::inverse(&c.llt(faer::Side::Lower).unwrap());
        let direct: f64 = (0..4).flat_map(|i| (0..4).map(move |j| (i, j))).map(|(i, j)| r[i] * inv[(i, j)] * r[j]).sum();
        let s = mahalanobis(&c, &r, None).unwrap();
        assert!((s.statistic - direct).abs() < 1e-12 && s.dof == 4);
        // T one column: β̂ = (TᵀC⁻¹r)/(TᵀC⁻¹T); the residual e = r − T β̂, eᵀC⁻¹e.
        let t = Mat::from_fn(4, 1, |i, _| 1.0 + i as f64);
        let tc = |v: &dyn Fn(usize) -> f64| -> f64 {
            (0..4).flat_map(|i| (0..4).map(move |j| (i, j))).map(|(i, j)| t[(i, 0)] * inv[(i, j)] * v(j)).sum()
        };
        let beta = tc(&|j| r[j]) / tc(&|j| t[(j, 0)]);
        let e: Vec<f64> = (0..4).map(|i| r[i] - t[(i, 0)] * beta).collect();
        let expected: f64 = (0..4).flat_map(|i| (0..4).map(move |j| (i, j))).map(|(i, j)| e[i] * inv[(i, j)] * e[j]).sum();
        let s = mahalanobis(&c, &r, Some(&t)).unwrap();
        assert!((s.statistic - expected).abs() < 1e-12, "{} vs {expected}", s.statistic);
        assert_eq!(s.dof, 3);
    }
}

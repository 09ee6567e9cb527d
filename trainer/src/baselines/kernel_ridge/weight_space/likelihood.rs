//! The peer's profiled evidence in weight space and its gradient. At unit amplitude, with
//! Λ = diag(λ_f), λ_f = Π_d ω_{h_d}(b_d), A' = A Λ^½, M = I + A'ᵀA'/ν, W̄ = M⁻¹A'ᵀR/ν (r × m) and
//! E = R − A'W̄, the quadratic form and the log determinant of C = K_V + ν I are
//!
//! ```text
//! Q = Σ_c rᵀ_c C⁻¹ r_c = |E|²/ν + |W̄|²          D = ln det C = N ln ν + ln det M
//! ∂Q/∂ln λ_k = −Σ_c w̄²_{k,c}                     ∂D/∂ln λ_k = 1 − (M⁻¹)_kk
//! ∂Q/∂ln ν   = −|E|²/ν                            ∂D/∂ln ν   = N − r + tr M⁻¹
//! ```
//!
//! and with γ̂ = Q/(N m) profiled out (as the kernel form's search does):
//! nlml = (N m/2)(1 + ln γ̂ + ln 2π) + (m/2) D, ∂nlml = (N m/2) ∂Q/Q + (m/2) ∂D.

use super::ResidualWeightSpace;
use crate::evidence::search::Criterion;
use crate::evidence::weight_space::absolute_tolerances;
use crate::evidence::weight_space::prior::PeriodicShares;
use crate::numeric::FIXED_SPLIT;
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::llt::factor::{cholesky_in_place, cholesky_in_place_scratch};
use faer::linalg::cholesky::llt::inverse::{inverse as llt_inverse, inverse_scratch as llt_inverse_scratch};
use faer::linalg::matmul::matmul;
use faer::linalg::triangular_solve::{solve_lower_triangular_in_place, solve_upper_triangular_in_place};
use faer::{Accum, Mat};

/// The profiled negative log marginal likelihood at one θ, γ̂ there, and the gradient in (ln b_d, ln ν).
pub(crate) struct Profiled {
    pub nlml: f64,
    pub gamma: f64,
    pub gradient: Vec<f64>,
}

impl ResidualWeightSpace {
    /// [`Profiled`] at `packed` = (ln b_1 … ln b_n, ln ν); `None` where M is not positive definite.
    pub(crate) fn profiled(&self, packed: &[f64]) -> Option<Profiled> {
        let (n, m, count, r) = (self.n, self.m, self.count, self.weights());
        let nu = packed[n].exp();
        let prior = PeriodicShares::new(&packed[..n], &self.orders);
        let scale: Vec<f64> = prior.shares.iter().map(|s| s.sqrt()).collect();
        // M = I + Λ^½ AᵀA Λ^½ / ν and A'ᵀR/ν.
        let mut l = Mat::from_fn(r, r, |k, j| scale[k] * scale[j] * self.gram[(k, j)] / nu + if k == j { 1.0 } else { 0.0 });
        let mut w = Mat::from_fn(r, m, |k, c| scale[k] * self.projection[(k, c)] / nu);
        let mut mem = MemBuffer::new(cholesky_in_place_scratch::<f64>(r, FIXED_SPLIT, Default::default()));
        cholesky_in_place(l.as_mut(), Default::default(), FIXED_SPLIT, MemStack::new(&mut mem), Default::default()).ok()?;
        let logdet_m: f64 = 2.0 * (0..r).map(|k| l[(k, k)].ln()).sum::<f64>();
        solve_lower_triangular_in_place(l.as_ref(), w.as_mut(), FIXED_SPLIT);
        solve_upper_triangular_in_place(l.as_ref().transpose(), w.as_mut(), FIXED_SPLIT);
        // E = R − A Λ^½ W̄, formed (not expanded through the Gram matrix: |E|² ≪ |R|²).
        let weights = Mat::from_fn(r, m, |k, c| scale[k] * w[(k, c)]);
        let mut e = self.residual.clone();
        matmul(e.as_mut(), Accum::Add, self.design.as_ref(), weights.as_ref(), -1.0, FIXED_SPLIT);
        let e2: f64 = (0..m).map(|c| (0..count).map(|i| e[(i, c)] * e[(i, c)]).sum::<f64>()).sum();
        let w2_by_function: Vec<f64> = (0..r).map(|k| (0..m).map(|c| w[(k, c)] * w[(k, c)]).sum()).collect();
        let quadratic = e2 / nu + w2_by_function.iter().sum::<f64>();
        let logdet = count as f64 * nu.ln() + logdet_m;
        let observations = (count * m) as f64;
        let gamma = quadratic / observations;
        let nlml = 0.5 * observations * (1.0 + gamma.ln() + (2.0 * std::f64::consts::PI).ln()) + 0.5 * m as f64 * logdet;
        if !(gamma > 0.0) || !nlml.is_finite() {
            return None;
        }
        // diag M⁻¹ (from the lower triangle of the inverse).
        let mut inv = Mat::<f64>::zeros(r, r);
        let mut mem = MemBuffer::new(llt_inverse_scratch::<f64>(r, FIXED_SPLIT));
        llt_inverse(inv.as_mut(), l.as_ref(), FIXED_SPLIT, MemStack::new(&mut mem));
        let (q_weight, d_weight) = (0.5 * observations / quadratic, 0.5 * m as f64);
        let mut gradient = vec![0.0; n + 1];
        for k in 0..r {
            let g = -q_weight * w2_by_function[k] + d_weight * (1.0 - inv[(k, k)]);
            for (d, &h) in self.orders[k * n..(k + 1) * n].iter().enumerate() {
                gradient[d] += g * prior.log_derivatives[d][h];
            }
        }
        let trace_inv: f64 = (0..r).map(|k| inv[(k, k)]).sum();
        gradient[n] = -q_weight * e2 / nu + d_weight * (count as f64 - r as f64 + trace_inv);
        gradient.iter().all(|g| g.is_finite()).then_some(Profiled { nlml, gamma, gradient })
    }
}

impl Criterion for ResidualWeightSpace {
    fn observations(&self) -> usize {
        self.count * self.m
    }

    /// Absolute, as CbD's weight space ([`absolute_tolerances`]).
    fn tolerances(&self) -> (f64, f64) {
        absolute_tolerances(self.observations())
    }

    fn nlml_and_gradient(&self, packed: &[f64]) -> Option<(f64, Vec<f64>)> {
        self.profiled(packed).map(|p| (p.nlml, p.gradient))
    }
}

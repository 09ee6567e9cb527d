//! The evidence: negative log marginal likelihood of the linearised model and its gradient.

use super::search::{Criterion, Partial};
use super::table::{Factored, PairTable, Theta};

impl Criterion for PairTable {
    fn observations(&self) -> usize {
        self.dim()
    }
    /// Negative log marginal likelihood (normalised units) and its gradient with respect to θ's
    /// packed form; `None` when K is not positive definite.
    fn nlml_and_gradient(&self, packed: &[f64]) -> Option<(f64, Vec<f64>)> {
        let (value, factored) = self.nlml(packed)?;
        Some((value, self.gradient_from(packed, factored)?))
    }
    /// The value from the Cholesky factor alone; the factor is what the gradient reuses.
    fn nlml(&self, packed: &[f64]) -> Option<(f64, Partial)> {
        let theta = Theta::unpack(packed, self.n);
        let dim = self.dim();
        let f = self.factor(&theta)?;
        let logdet: f64 = 2.0 * (0..dim).map(|i| f.l[(i, i)].ln()).sum::<f64>();
        let value = 0.5 * f.quad + 0.5 * logdet + 0.5 * dim as f64 * (2.0 * std::f64::consts::PI).ln();
        value.is_finite().then(|| (value, Box::new(f) as Partial))
    }
    fn gradient_from(&self, packed: &[f64], partial: Partial) -> Option<Vec<f64>> {
        let f = partial.downcast::<Factored>().ok()?;
        let theta = Theta::unpack(packed, self.n);
        let inv = f.inverse();
        // ∂ nlml / ∂θ = ½ tr(Q ∂K/∂θ), Q = K⁻¹ − α αᵀ.
        Some(self.half_trace_gradient(&theta, &f, |r, c| inv.at(r, c) - f.alpha[(r, 0)] * f.alpha[(c, 0)]))
    }
}

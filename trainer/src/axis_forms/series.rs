//! A joint-kernel axis form's own series (docs/DESIGN.md §11): per order, its share of the kernel's
//! total weight and the prior variance of its basis functions — what the expansion truncates.

use super::weights::{gaussian_weights, periodic_weights};
use cbd_protocol::MAX_EXPANSION_ORDER;

/// One axis of a product kernel: for each order, its share of the total weight (summing to one) and
/// the prior variance of each of its basis functions; periodic orders h ≥ 1 have two (cos, sin).
#[derive(Debug, Clone)]
pub struct AxisSeries {
    pub share: Vec<f64>,
    pub variance: Vec<f64>,
    pub periodic: bool,
}

impl AxisSeries {
    /// The periodic kernel exp(b (cos Δ − 1)): share = variance = e^{−b} I_h(b) (2 − δ_h0) … per function ω_h (cos and sin each).
    pub fn periodic(b: f64) -> AxisSeries {
        let w = periodic_weights(b, MAX_EXPANSION_ORDER as usize);
        // Each of cos hx cos hx' + sin hx sin hx' carries the whole ω_h as its prior variance.
        AxisSeries { variance: w.clone(), share: w, periodic: true }
    }
    /// A Gaussian factor exp(−Δ²/2ℓ²) on |x| ≤ ρ ℓ: share = Poisson(ρ²), variance 1 (the features carry 1/√k!).
    pub fn gaussian(rho: f64) -> AxisSeries {
        let share = gaussian_weights(rho, MAX_EXPANSION_ORDER as usize);
        AxisSeries { variance: vec![1.0; share.len()], share, periodic: false }
    }
}

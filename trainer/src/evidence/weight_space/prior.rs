//! The prior variances of the periodic joint functions: for function f with order h_fd on axis d,
//! its share of the unit product kernel λ_f = Π_d ω_{h_fd}(b_d) (docs/DESIGN.md §11), with
//! d ln λ_f / d ln b_d = d ln ω_{h_fd} / d ln b_d for the chain rule to the widths.

use crate::axis_forms::weights::periodic_weights_and_log_derivatives;

/// Shares and log-derivatives at log widths `log_widths` for functions of orders `orders` (r × n).
pub(crate) struct PeriodicShares {
    /// λ_f, one per function.
    pub shares: Vec<f64>,
    /// Per axis d, d ln ω_h / d ln b_d by order h.
    pub log_derivatives: Vec<Vec<f64>>,
}

impl PeriodicShares {
    pub(crate) fn new(log_widths: &[f64], orders: &[usize]) -> PeriodicShares {
        let n = log_widths.len();
        let max_order = orders.iter().copied().max().unwrap_or(0);
        let (weights, log_derivatives): (Vec<Vec<f64>>, Vec<Vec<f64>>) =
            log_widths.iter().map(|lb| periodic_weights_and_log_derivatives(lb.exp(), max_order)).unzip();
        let shares = orders.chunks_exact(n.max(1)).map(|of| of.iter().zip(&weights).map(|(&h, w)| w[h]).product::<f64>()).collect();
        PeriodicShares { shares, log_derivatives }
    }
}

//! Which basis functions an expansion keeps (docs/DESIGN.md §11): the modes of a product kernel
//! with the largest shares of its total weight, until what is dropped is at most the tolerance.

use super::weights::{gaussian_weights, periodic_weights};
use cbd_protocol::MAX_EXPANSION_ORDER;

/// Modes enumerated at most while searching for the truncation (a guard on time and memory: a
/// kernel that needs more is kept in the kernel form).
const MAX_MODES: usize = 200_000;

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

/// A kept basis: per function, its code per axis (the protocol's encoding) and prior variance.
#[derive(Debug, Clone, PartialEq)]
pub struct Basis {
    /// functions × axes codes, row-major: periodic `h << 1 | sin`, Gaussian `k << 1`.
    pub codes: Vec<u8>,
    pub variances: Vec<f64>,
    /// The share of the kernel's total weight the dropped modes carry (≤ the tolerance).
    pub dropped: f64,
}

impl Basis {
    pub fn len(&self) -> usize {
        self.variances.len()
    }
    pub fn is_empty(&self) -> bool {
        self.variances.is_empty()
    }
}

/// The modes of the product of `axes` with the largest shares such that the shares dropped add up to
/// at most `tolerance`; `None` when that needs an order above the protocol's limit or more than
/// [`MAX_MODES`] modes.
pub fn truncate(axes: &[AxisSeries], tolerance: f64) -> Option<Basis> {
    // Each axis's orders by decreasing share (a Poisson's are not monotone), with the order's share.
    let sorted: Vec<Vec<(usize, f64)>> = axes
        .iter()
        .map(|a| {
            let mut o: Vec<(usize, f64)> = a.share.iter().copied().enumerate().collect();
            o.sort_by(|x, y| y.1.total_cmp(&x.1).then(x.0.cmp(&y.0)));
            o
        })
        .collect();
    // The share an axis leaves beyond its highest order must itself fit in the tolerance.
    let beyond: f64 = axes.iter().map(|a| (1.0 - a.share.iter().sum::<f64>()).max(0.0)).sum();
    if beyond > 0.5 * tolerance {
        return None;
    }
    let mut threshold = tolerance;
    loop {
        let mut modes: Vec<(f64, Vec<usize>)> = Vec::new();
        if !enumerate(&sorted, threshold, 0, 1.0, &mut Vec::new(), &mut modes) {
            return None;
        }
        // Largest share first; ties by order, so the basis does not depend on enumeration order.
        modes.sort_by(|a, b| b.0.total_cmp(&a.0).then_with(|| a.1.cmp(&b.1)));
        // Dropped = 1 − kept, summed from the smallest terms (accurate to ~1e-16).
        let kept: f64 = modes.iter().rev().fold(0.0, |s, m| s + m.0);
        let mut dropped = (1.0 - kept).max(0.0) + beyond;
        if dropped <= tolerance {
            while let Some(last) = modes.last() {
                if dropped + last.0 > tolerance {
                    break;
                }
                dropped += last.0;
                modes.pop();
            }
            return Some(expand_modes(axes, &modes, dropped));
        }
        if threshold < 1e-300 {
            return None;
        }
        threshold *= 1e-2;
    }
}

/// Depth-first over the axes, pruning products below `threshold` (orders sorted by share).
fn enumerate(
    sorted: &[Vec<(usize, f64)>],
    threshold: f64,
    axis: usize,
    product: f64,
    prefix: &mut Vec<usize>,
    out: &mut Vec<(f64, Vec<usize>)>,
) -> bool {
    if axis == sorted.len() {
        out.push((product, prefix.clone()));
        return out.len() <= MAX_MODES;
    }
    for &(order, share) in &sorted[axis] {
        let p = product * share;
        if p < threshold {
            break;
        }
        prefix.push(order);
        let ok = enumerate(sorted, threshold, axis + 1, p, prefix, out);
        prefix.pop();
        if !ok {
            return false;
        }
    }
    true
}

/// The basis functions of `modes`: a periodic order h ≥ 1 gives cos and sin, every other order one.
fn expand_modes(axes: &[AxisSeries], modes: &[(f64, Vec<usize>)], dropped: f64) -> Basis {
    let mut codes = Vec::new();
    let mut variances = Vec::new();
    for (_, orders) in modes {
        let variance: f64 = orders.iter().zip(axes).map(|(&o, a)| a.variance[o]).product();
        // Phases: one bit per periodic axis of order ≥ 1, in axis order.
        let phased: Vec<usize> = orders.iter().zip(axes).enumerate().filter(|(_, (&o, a))| a.periodic && o > 0).map(|(d, _)| d).collect();
        for bits in 0..(1usize << phased.len()) {
            for (d, &o) in orders.iter().enumerate() {
                let sin = phased.iter().position(|&p| p == d).map_or(0, |i| (bits >> i) & 1);
                codes.push(((o as u8) << 1) | sin as u8);
            }
            variances.push(variance);
        }
    }
    Basis { codes, variances, dropped }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn flat_periodic_kernels_need_few_modes_and_the_dropped_share_is_honest() {
        let axes = [AxisSeries::periodic(0.0037), AxisSeries::periodic(0.0023)];
        let basis = truncate(&axes, 1e-13).unwrap();
        assert!(basis.dropped <= 1e-13);
        // Orders up to 4 or 5 per axis at most: a short expansion.
        assert!(basis.len() < 120, "{} functions", basis.len());
        // The kept variances (one per mode, counted once per phase pattern) plus the dropped share make one.
        let mut kept = 0.0;
        for (f, v) in basis.variances.iter().enumerate() {
            let codes = &basis.codes[2 * f..2 * f + 2];
            if codes.iter().all(|c| c & 1 == 0) {
                kept += v;
            }
        }
        assert!((kept + basis.dropped - 1.0).abs() < 1e-15, "{kept} + {}", basis.dropped);
    }

    #[test]
    fn narrow_kernels_are_refused() {
        assert!(truncate(&[AxisSeries::periodic(204.0), AxisSeries::periodic(204.0)], 1e-13).is_none());
        assert!(truncate(&[AxisSeries::gaussian(9.0)], 1e-13).is_none());
    }

    #[test]
    fn gaussian_axes_use_powers_without_phases() {
        let basis = truncate(&[AxisSeries::gaussian(0.2), AxisSeries::gaussian(0.2)], 1e-12).unwrap();
        assert!(basis.codes.iter().all(|c| c & 1 == 0));
        assert!(basis.variances.iter().all(|v| *v == 1.0));
        assert!(basis.dropped <= 1e-12);
    }
}

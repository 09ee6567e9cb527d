//! Which basis functions an expansion keeps (docs/DESIGN.md §11): the modes of a product kernel
//! with the largest shares of its total weight, until what is dropped is at most the tolerance.

pub use crate::axis_forms::series::AxisSeries;

/// Modes enumerated at most while searching for the truncation (a guard on time and memory: a
/// kernel that needs more is kept in the kernel form).
const MAX_MODES: usize = 200_000;

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

//! Position-error statistics: mean, median, 99th percentile, maximum.

use serde::Serialize;

/// Euclidean distance between each predicted and measured row of `dim` values.
pub fn position_errors(predicted: &[f64], measured: &[f64], dim: usize) -> Vec<f64> {
    predicted
        .chunks_exact(dim)
        .zip(measured.chunks_exact(dim))
        .map(|(p, y)| p.iter().zip(y).map(|(a, b)| (a - b) * (a - b)).sum::<f64>().sqrt())
        .collect()
}

/// The p-quantile of sorted values, interpolated linearly between order statistics (NaN when empty).
pub fn quantile(sorted: &[f64], p: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let pos = p * (sorted.len() - 1) as f64;
    let lo = pos.floor() as usize;
    let hi = pos.ceil() as usize;
    sorted[lo] + (sorted[hi] - sorted[lo]) * (pos - lo as f64)
}

/// Median of the finite values (NaN when there are none).
pub fn median(values: &[f64]) -> f64 {
    let mut v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
    v.sort_by(|a, b| a.total_cmp(b));
    quantile(&v, 0.5)
}

#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ErrorStats {
    pub mean: f64,
    pub median: f64,
    pub p99: f64,
    pub max: f64,
}

impl ErrorStats {
    /// Statistics of Euclidean errors between predicted and measured rows of `dim` values.
    pub fn of_positions(predicted: &[f64], measured: &[f64], dim: usize) -> ErrorStats {
        ErrorStats::of_errors(&position_errors(predicted, measured, dim))
    }

    /// Statistics of a list of non-negative errors (NaN sorts last and poisons the mean).
    pub fn of_errors(errors: &[f64]) -> ErrorStats {
        if errors.is_empty() {
            return ErrorStats { mean: f64::NAN, median: f64::NAN, p99: f64::NAN, max: f64::NAN };
        }
        let mut sorted = errors.to_vec();
        sorted.sort_by(|a, b| a.total_cmp(b));
        let q = |p: f64| quantile(&sorted, p);
        ErrorStats { mean: errors.iter().sum::<f64>() / errors.len() as f64, median: q(0.5), p99: q(0.99), max: sorted[sorted.len() - 1] }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn statistics_of_a_known_list() {
        let e: Vec<f64> = (1..=101).map(|v| v as f64).collect();
        let s = ErrorStats::of_errors(&e);
        assert_eq!((s.mean, s.median, s.max), (51.0, 51.0, 101.0));
        assert!((s.p99 - 100.0).abs() < 1e-12);
        let s = ErrorStats::of_positions(&[3.0, 4.0, 0.0, 0.0], &[0.0, 0.0, 0.0, 1.0], 2);
        assert_eq!((s.mean, s.max), (3.0, 5.0));
    }
}

//! Bounds every imported value obeys.

/// Largest magnitude of an imported value in the model's unit. Squares and sums of squares of
/// differences (distances, kernel arguments, σ²) must stay finite; 1e100² is still far from f64's
/// 1.8e308, and no arm is measured beyond 1e100 of any unit.
pub const MAX_MAGNITUDE: f64 = 1e100;

/// Smallest magnitude of a positive scale read from a flag or a blob (σ, kernel widths and gains):
/// below it, a scale is no length of any arm (f64 subnormals start at 2.2e-308) and its inverse
/// square would overflow.
pub const MIN_POSITIVE: f64 = 1e-100;

/// A positive scale (σ, a kernel width or gain) out of [`MIN_POSITIVE`, `MAX_MAGNITUDE`]: the
/// refusal's text, `what` (a flag, a blob's field) and the value as written; `None` within.
pub fn positive_scale_out_of_bounds(what: &str, v: f64) -> Option<String> {
    if (MIN_POSITIVE..=MAX_MAGNITUDE).contains(&v) {
        return None;
    }
    Some(format!("{what} must be a number in [{MIN_POSITIVE:e}, {MAX_MAGNITUDE:e}], got {}", crate::error::as_written(v)))
}

#[cfg(test)]
mod tests {
    /// Issue 51 class 3: one bound for σ and the kernels' scales, wherever they are read.
    #[test]
    fn positive_scales_have_one_bound() {
        for v in [1e-30, 1e30, 1.0, 1e-100, 1e100] {
            assert_eq!(super::positive_scale_out_of_bounds("--sigma", v), None);
        }
        for (v, shown) in [(1e300, "1e300"), (1e-310, "1e-310"), (0.0, "0"), (-1.0, "-1"), (f64::NAN, "NaN"), (f64::INFINITY, "inf")] {
            let e = super::positive_scale_out_of_bounds("noise_sigma", v).unwrap();
            assert_eq!(e, format!("noise_sigma must be a number in [1e-100, 1e100], got {shown}"));
        }
    }
}

//! Bounds every imported value obeys.

/// Largest magnitude of an imported value in the model's unit. Squares and sums of squares of
/// differences (distances, kernel arguments, σ²) must stay finite; 1e100² is still far from f64's
/// 1.8e308, and no arm is measured beyond 1e100 of any unit.
pub const MAX_MAGNITUDE: f64 = 1e100;

//! The weight-space search inside moving boxes (docs/DESIGN.md §3): a truncated basis covers a box of
//! θ around the point it was built at (narrower kernels and smaller σ need more functions); L-BFGS
//! stays inside it, and an optimum on one of the box's own faces rebuilds the basis there. Shared by
//! CbD's evidence and the kernel-ridge peer's.

use super::Declined;
use crate::evidence::search::{minimise, Criterion};
use std::cell::RefCell;

/// How far the box reaches from where its basis was built: joint b_d up to BOX × b_d, task width a
/// down to a / √BOX, σ down to σ / BOX (the truncation tolerance follows σ²).
pub(crate) const BOX: f64 = 3.0;
/// Times the box may move after an optimum on one of its faces.
const MAX_ROUNDS: usize = 3;

/// A criterion in a basis fixed for a box of θ.
pub(crate) trait BoxedCriterion: Criterion {
    /// Packed θ bounds of the box the basis covers (±∞ where it imposes none).
    fn box_bounds(&self) -> (&[f64], &[f64]);
}

/// Where L-BFGS stops in weight space, per unknown (as [`Criterion::tolerances`]): absolute, 1e-4 nats
/// of value change and 1e-3 nats per unit of log θ of gradient. The r × r system keeps the value to far
/// better than the kernel form's ±1 nat, and the optimum lies on flat ridges (widths against amplitudes):
/// with the kernel form's 1e-4 nats per unknown (0.8 nats at N m = 8192, 3.3 at 32768) CbD's search
/// stopped at its start or one step after it, up to a nat short (noisy RR, N = 4096).
pub(crate) fn absolute_tolerances(observations: usize) -> (f64, f64) {
    let per_unknown = 1.0 / observations.max(1) as f64;
    (1e-4 * per_unknown, 1e-3 * per_unknown)
}

/// The optimum found, the table (basis) it was found in, and the boxes used.
pub(crate) struct BoxedOptimum<T> {
    pub nlml: f64,
    pub param: Vec<f64>,
    pub table: T,
    pub rounds: usize,
}

/// L-BFGS from `start` inside the search bounds (`lower`, `upper`) and the box of the table `build`
/// makes around it; while the optimum lies on a face the box imposes (not the search's own bounds),
/// the table is rebuilt there (at most [`MAX_ROUNDS`] boxes). Errors: the table's, or no θ in the box
/// gave a positive-definite system.
pub(crate) fn minimise_in_boxes<T: BoxedCriterion>(
    build: impl Fn(&[f64]) -> Result<T, Declined>,
    start: &[f64],
    lower: &[f64],
    upper: &[f64],
    max_iterations: u64,
    evaluations: &RefCell<usize>,
) -> Result<BoxedOptimum<T>, Declined> {
    let mut param = start.to_vec();
    let mut rounds = 0;
    loop {
        rounds += 1;
        let table = build(&param)?;
        let (box_lower, box_upper) = table.box_bounds();
        let lo: Vec<f64> = lower.iter().zip(box_lower).map(|(a, b)| a.max(*b)).collect();
        let hi: Vec<f64> = upper.iter().zip(box_upper).map(|(a, b)| a.min(*b)).collect();
        let (nlml, found) = minimise(&table, &lo, &hi, &param, max_iterations, evaluations).ok_or(Declined::NotPositiveDefinite)?;
        let on_face =
            (0..found.len()).any(|k| (hi[k] < upper[k] && found[k] >= hi[k] - 1e-3) || (lo[k] > lower[k] && found[k] <= lo[k] + 1e-3));
        param = found;
        if !on_face || rounds == MAX_ROUNDS {
            return Ok(BoxedOptimum { nlml, param, table, rounds });
        }
    }
}

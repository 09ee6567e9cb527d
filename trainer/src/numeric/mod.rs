//! Numerical building blocks with no model in them, shared by the expansion, the solver, DH
//! calibration and diagnose (a layer below all of them, docs/DESIGN.md §1): linear least squares
//! (`least_squares`: QR and truncated SVD), the one nonlinear least-squares driver
//! (`levenberg_marquardt`, docs/DESIGN.md §3), how much a sum of kernel columns cancels
//! (`cancellation`), why a type-II maximum-likelihood search failed (`likelihood_search`) and faer's
//! fixed work split ([`FIXED_SPLIT`]).

pub mod cancellation;
pub mod least_squares;
pub mod levenberg_marquardt;
pub mod likelihood_search;

use faer::Par;

/// Faer's work split for the factorisations: fixed, so the arithmetic (and the blob) does not
/// depend on how many threads the pool running it has (`Par::Seq` would round differently).
pub const FIXED_SPLIT: Par = Par::Rayon(match std::num::NonZeroUsize::new(2) {
    Some(n) => n,
    None => unreachable!(),
});

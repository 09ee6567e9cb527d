//! The kernel-ridge peer as every command runs it: its own hyperparameters (maximum marginal
//! likelihood of its GP on the rows given), then the regression (K + σ² I) α = y − k0 with them.

use super::fit::KernelRidge;
use super::selection::{choose_kernel_ridge_hyperparameters, Hyperparameters, SearchOptions};
use crate::data::Measurements;
use cbd_protocol::NominalModel;
use std::time::Instant;

/// A kernel ridge regression with the hyperparameters its own evidence chose.
#[derive(Debug, Clone)]
pub struct SelectedKernelRidge {
    pub regression: KernelRidge,
    pub hyperparameters: Hyperparameters,
    /// Wall time of the hyperparameter search.
    pub selection_seconds: f64,
    /// Wall time of the search and the fit together.
    pub seconds: f64,
}

/// Selects kernel ridge's hyperparameters on `data` (training rows only) and fits it with them: the
/// GP posterior mean ŷ = k0 + K(·, X) (K + σ² I)⁻¹ (y − k0) at the maximum of its marginal likelihood.
pub fn fit_kernel_ridge_peer(nominal: &NominalModel, data: &Measurements, search: &SearchOptions) -> crate::Result<SelectedKernelRidge> {
    let start = Instant::now();
    let hyperparameters = choose_kernel_ridge_hyperparameters(nominal, data, search)?;
    let selection_seconds = start.elapsed().as_secs_f64();
    let regression = KernelRidge::fit(nominal, data, hyperparameters.kernel.clone(), hyperparameters.ridge())?;
    Ok(SelectedKernelRidge { regression, hyperparameters, selection_seconds, seconds: start.elapsed().as_secs_f64() })
}

//! The kernel-ridge (Gaussian-process regression) peer of the residual y − k0(x): its regression
//! ([`fit`]), its own hyperparameter selection by its GP's marginal likelihood ([`selection`]), and
//! the one path every command takes to both ([`peer`]), and that path as a correction for the
//! evaluation harnesses ([`correction`]).

pub mod correction;
pub mod fit;
pub mod peer;
pub mod selection;
pub mod weight_space;

pub use correction::kernel_ridge_correction;
pub use fit::{kernel_matrix, KernelRidge, KrrError};
pub use peer::{fit_kernel_ridge_peer, SelectedKernelRidge};
pub use selection::{choose_kernel_ridge_hyperparameters, HyperparameterError, Hyperparameters, SearchOptions};
pub use weight_space::KrrWeightSpaceReport;

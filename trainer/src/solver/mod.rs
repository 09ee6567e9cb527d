//! Minimises energy (16) over the initial momenta for the discrete flow the runtime integrates:
//! Levenberg–Marquardt on the stacked residual, exact Jacobian from the tangent flow,
//! warm-started from the linearised (kernel) model.

pub mod allocator;
pub mod cancellation;
pub mod least_squares;
pub mod levenberg_marquardt;
pub mod regulariser;
pub mod step;
pub mod subspace;

pub use levenberg_marquardt::{
    fit_cbd, CbdFit, CbdOptions, FitError, FitReport, IterationLog, SolverMethod, DENSE_MAX_UNKNOWNS, FIXED_SPLIT,
};

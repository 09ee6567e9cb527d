//! Minimises energy (16) over the initial momenta for the discrete flow the runtime integrates
//! (`fit`): in closed form for the linear scheme, else Levenberg–Marquardt on the stacked residual
//! with the exact Jacobian from the tangent flow, warm-started from the linearised model.

pub mod allocator;
pub mod cancellation;
pub mod fit;
pub mod least_squares;
pub mod regulariser;
pub mod step;
pub mod subspace;

pub use fit::{fit_cbd, CbdFit, CbdOptions, FitError, FitReport, IterationLog, SolverMethod, DENSE_MAX_UNKNOWNS, FIXED_SPLIT};

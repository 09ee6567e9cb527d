//! Minimises energy (16) over the initial momenta for the discrete flow the runtime integrates
//! (`fit`): in closed form for the linear scheme, else Levenberg–Marquardt on the stacked residual
//! with the exact Jacobian from the tangent flow, warm-started from the linearised model.
//! `levenberg_marquardt` is the trainer's one nonlinear least-squares driver: the flow fit, the
//! expansion's multi-step fit, DH calibration and diagnose's refinement all run on it.

pub mod allocator;
pub mod cancellation;
pub mod fit;
pub mod least_squares;
pub mod levenberg_marquardt;
pub mod regulariser;
pub mod step;
pub mod subspace;

pub use fit::{
    fit_cbd, CbdFit, CbdOptions, FitError, FitReport, FlowHyperparameters, IterationLog, SolverMethod, DENSE_MAX_UNKNOWNS, FIXED_SPLIT,
};

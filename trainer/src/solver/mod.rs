//! Minimises energy (16) over the initial momenta for the discrete flow the runtime integrates
//! (`fit`): in closed form for the linear scheme, else Levenberg–Marquardt on the stacked residual
//! with the exact Jacobian from the tangent flow, warm-started from the linearised model. The
//! Levenberg–Marquardt driver, the linear least squares and the cancellation measure it runs on are
//! `crate::numeric`'s (a layer below, shared with the expansion, DH calibration and diagnose).

pub mod allocator;
pub mod fit;
pub mod regulariser;
pub mod step;
pub mod subspace;

pub use fit::{
    fit_cbd, predict_with_configuration, solve_with_configuration, CbdFit, CbdOptions, FitError, FitReport, FlowHyperparameters,
    IterationLog, SolverMethod, SolverSettings, DENSE_MAX_UNKNOWNS,
};

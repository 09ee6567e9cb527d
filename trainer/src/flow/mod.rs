//! The discrete flow in the trainer. The primal is the runtime's own code (bit-identical
//! discrete model); the tangent (its derivative with respect to the initial momenta) sits beside it.

pub mod primal;
pub mod tangent;

pub use primal::{ControlPoints, PrimalFlow};

//! The discrete flow in the trainer. The primal is the runtime's own code (bit-identical
//! discrete model); the tangent (its derivative with respect to the initial momenta) sits beside it.

pub mod primal;
pub mod tangent;

pub use primal::{ControlPoints, PrimalFlow};

/// Runs `f` on a pool of `threads` threads, or on the command's pool when called there
/// ([`crate::memory::on_workers`]). The arithmetic never depends on the count: work is split into
/// a fixed number of pieces (see `numeric::FIXED_SPLIT` and the tangent's column chunks).
pub fn with_threads<R: Send>(threads: usize, f: impl FnOnce() -> R + Send) -> R {
    crate::memory::on_workers(threads, f)
}

//! Evaluates a calibrated model k1 = ψ ∘ k0 ∘ φ⁻¹ (Calibration by Diffeomorphisms) on a
//! controller: `#![no_std]`, no heap, fixed-step integration of eq. (20), position and Jacobian.
//!
//! ```ignore
//! let mut storage = [0.0; 200_000]; // Real values (f64, or f32 with the `f32` feature), ≥ storage_len_for(&model)
//! let mut cal = Calibrator::load(BLOB, &mut storage)?;
//! let e = cal.evaluate(&[0.3, -1.2])?;
//! let (y, dy) = (e.position(), e.jacobian());
//! ```
//!
//! The controller's API is the crate root, and nothing else: [`Calibrator`] (load, `evaluate`,
//! `compensate`; with several tool points per pose `evaluate_point`, `evaluate_pose`,
//! `compensate_pose`), [`Evaluation`], [`PoseEvaluation`], [`Compensation`] and
//! [`CompensateOptions`] (and their pose forms), [`storage_len_for`] (and the kernel form's
//! [`storage_len`]), [`Error`], the scalar [`Real`] and the sizing constants [`MAX_JOINTS`],
//! [`MAX_TASK_DIM`]. `tests/face.rs` pins this list: a change of the face is a visible diff.
//! `Calibrator`'s methods wrap the functions of the private modules that own the operations (`load`,
//! `evaluate`, `pose`, `flow_maps`, `compensate`, `compensate_pose`), each taking the loaded model
//! first, pinocchio's `algorithm(model, data, q)`. The building blocks below them are shared with
//! the trainer, so that it optimises exactly what the controller evaluates (same code, same bits),
//! through [`internals`] — marked as such and outside the controller's API: `kinematics` (k0 and
//! its derivatives), `kernel`, `flow` (eq. 17, 19, 20, the control points' integration, the query's
//! derivatives, the inverse flows' pieces), `expansion` (format 5: the fields in their kernels' own
//! basis), `integrate`, `real`, and `inverse_kinematics` (the nominal closed forms compensation
//! starts from). docs/DESIGN.md §1 lists the layers; no module imports from a layer above its own.
#![no_std]
#![deny(missing_docs)]
#![cfg_attr(not(test), deny(clippy::unwrap_used, clippy::expect_used, clippy::panic, clippy::indexing_slicing))]
// `!(a >= b)` is how this crate writes "a < b, or NaN": a non-finite value takes the refusing branch.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

// The controller's face: the names below, at the crate root. Every module is private; what the
// trainer shares (so that it optimises exactly what the controller evaluates) is in `internals`.
mod calibrator;
mod compensate;
mod compensate_pose;
mod error;
mod evaluate;
mod expansion;
mod flow;
mod flow_maps;
mod integrate;
mod inverse_kinematics;
mod kernel;
mod kinematics;
mod load;
mod pose;
mod precision;
mod real;

pub use cbd_protocol::{MAX_JOINTS, MAX_TASK_DIM};
pub use compensate::{CompensateOptions, Compensation};
pub use compensate_pose::{PoseCompensateOptions, PoseCompensation};
pub use error::Error;
pub use evaluate::Evaluation;
pub use load::{storage_len, storage_len_for, Calibrator};
pub use pose::PoseEvaluation;
pub use real::Real;

/// The building blocks the trainer (and the workspace's tests) share with the controller, so that
/// the trainer optimises exactly what the controller evaluates — same code, same bits. **Not part
/// of the controller's API**: no stability promise; firmware uses the crate root alone.
pub mod internals {
    /// Nominal forward kinematics k0 and its derivatives.
    pub mod kinematics {
        pub use crate::kinematics::*;
    }
    /// The joint and task kernels and their features.
    pub mod kernel {
        pub use crate::kernel::*;
    }
    /// Eq. (17), (19), (20): the control points' integration, the query's derivatives, the inverse flows' pieces.
    pub mod flow {
        pub use crate::flow::*;
    }
    /// Format 5: the fields in their kernels' own basis.
    pub mod expansion {
        pub use crate::expansion::*;
    }
    /// The fixed-step integrators.
    pub mod integrate {
        pub use crate::integrate::*;
    }
    /// The nominal closed forms compensation starts from.
    pub mod inverse_kinematics {
        pub use crate::inverse_kinematics::*;
    }
    /// The evaluation's scalar and its elementary functions.
    pub mod real {
        pub use crate::real::*;
    }
    /// Full-pose compensation's pieces the trainer reports with.
    pub mod compensate_pose {
        pub use crate::compensate_pose::{nominal_pose_inverse, tool_lever, MIN_POSE_JOINTS};
    }
}

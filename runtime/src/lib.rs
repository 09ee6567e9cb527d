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
//! The controller's API is at the crate root: [`Calibrator`] (load, `evaluate`, `compensate`; with
//! several tool points per pose `evaluate_point`, `evaluate_pose`, `compensate_pose`),
//! [`Evaluation`], [`PoseEvaluation`], [`storage_len_for`] (and the kernel form's [`storage_len`]), [`Error`]. The modules are the building blocks the trainer
//! shares so that it optimises exactly what the controller evaluates (same code, same bits):
//! `kinematics` (k0 and its derivatives), `kernel`, `flow` (eq. 17, 19, 20, the control points'
//! integration, the query's derivatives, the inverse flows), `expansion` (format 5: the fields in
//! their kernels' own basis, evaluated instead of the kernel form when the blob has them), `integrate`, `real`, and
//! `inverse_kinematics` (the nominal closed forms compensation starts from).
#![no_std]
#![deny(missing_docs)]
#![cfg_attr(not(test), deny(clippy::unwrap_used, clippy::expect_used, clippy::panic, clippy::indexing_slicing))]
// `!(a >= b)` is how this crate writes "a < b, or NaN": a non-finite value takes the refusing branch.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod calibrator;
pub mod compensate;
pub mod compensate_pose;
pub mod expansion;
pub mod flow;
pub mod integrate;
pub mod inverse_kinematics;
pub mod kernel;
pub mod kinematics;
pub mod pose;
pub mod precision;
pub mod real;

pub use calibrator::{storage_len, storage_len_for, Calibrator, Evaluation};
pub use cbd_protocol as protocol;
pub use compensate::{CompensateOptions, Compensation};
pub use compensate_pose::{PoseCompensateOptions, PoseCompensation};
pub use pose::PoseEvaluation;

/// Why loading or evaluation failed. The runtime returns these; it never panics.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Error {
    /// The blob was rejected (frame, checksum, version or contents).
    Blob(cbd_protocol::DecodeError),
    /// The caller's storage is smaller than [`storage_len_for`] this model.
    StorageTooSmall {
        /// Values the model needs.
        needed: usize,
        /// Values the caller gave.
        got: usize,
    },
    /// The query has the wrong number of joints.
    QueryDimension {
        /// The model's joints.
        expected: usize,
        /// The query's coordinates.
        found: usize,
    },
    /// A query coordinate is NaN or infinite.
    NonFiniteQuery {
        /// The joint.
        index: usize,
    },
    /// A compensation target has the wrong number of coordinates.
    TargetDimension {
        /// The model's task dimension.
        expected: usize,
        /// The target's coordinates.
        found: usize,
    },
    /// A compensation target coordinate is NaN or infinite.
    NonFiniteTarget {
        /// The coordinate.
        index: usize,
    },
    /// A tool point beyond the model's ([`cbd_protocol::NominalModel::tool_point_count`]).
    ToolPoint {
        /// The tool point asked for.
        index: usize,
        /// The model's tool points.
        count: usize,
    },
    /// The tool frame's orientation is undetermined: fewer than 3 tool points, or all on one line.
    OrientationUndetermined,
    /// A pose target on an arm with too few joints ([`compensate_pose::MIN_POSE_JOINTS`]).
    TooFewJoints {
        /// The model's joints.
        found: usize,
        /// The joints a pose target needs.
        needed: usize,
    },
    /// A target rotation that is not a rotation (not orthonormal, or a reflection).
    InvalidRotation,
    /// The control points' flow produced a non-finite value.
    Diverged,
    /// The query's flow produced a non-finite value.
    NonFiniteResult,
    /// An internal size invariant failed (a bug, reported instead of panicking).
    Internal,
}

impl core::fmt::Display for Error {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Error::Blob(e) => write!(f, "{e}"),
            Error::StorageTooSmall { needed, got } => write!(f, "storage too small: model needs {needed} values, got {got}"),
            Error::QueryDimension { expected, found } => write!(f, "query has {found} joints, model has {expected}"),
            Error::NonFiniteQuery { index } => write!(f, "query joint {index} is not finite"),
            Error::TargetDimension { expected, found } => write!(f, "target has {found} coordinates, model has {expected}"),
            Error::NonFiniteTarget { index } => write!(f, "target coordinate {index} is not finite"),
            Error::ToolPoint { index, count } => write!(f, "tool point {index} asked for; the model has {count}"),
            Error::OrientationUndetermined => {
                write!(f, "the tool frame's orientation is undetermined (fewer than 3 tool points, or all on one line)")
            }
            Error::TooFewJoints { found, needed } => write!(f, "a pose target needs {needed} joints; the model has {found}"),
            Error::InvalidRotation => write!(f, "the target rotation is not a rotation (not orthonormal, or a reflection)"),
            Error::Diverged => write!(f, "the control points' flow diverged (non-finite state)"),
            Error::NonFiniteResult => write!(f, "evaluation produced a non-finite value"),
            Error::Internal => write!(f, "internal size invariant failed"),
        }
    }
}

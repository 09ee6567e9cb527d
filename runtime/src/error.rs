//! Why loading or evaluation failed: the one error type every module of the runtime returns.

/// Why loading or evaluation failed. The runtime returns these; it never panics.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Error {
    /// The blob was rejected (frame, checksum, version or contents).
    Blob(cbd_protocol::DecodeError),
    /// The caller's storage is smaller than [`crate::storage_len_for`] this model.
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
    /// A pose target on an arm with too few joints ([`crate::compensate_pose::MIN_POSE_JOINTS`]).
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

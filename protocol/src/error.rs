//! Why a model, a blob or an encoding was refused: the protocol's errors, below every module that
//! returns them.

use crate::format::OLDEST_FORMAT_VERSION;

/// What is wrong with a model, naming the field.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ModelError {
    /// A field holds NaN or ±∞.
    NonFinite {
        /// The field's path in the model.
        field: &'static str,
        /// The value's position in the field.
        index: usize,
    },
    /// A field is outside its allowed range (e.g. a width ≤ 0).
    OutOfRange {
        /// The field's path in the model (with the reason in parentheses where there are several).
        field: &'static str,
    },
    /// Array or table sizes disagree.
    Dimension {
        /// The field's path in the model.
        field: &'static str,
        /// The size the other fields imply.
        expected: usize,
        /// The field's size.
        found: usize,
    },
    /// A field of entry `index` of a list is outside its allowed range (e.g. the joint of an effect).
    OutOfRangeAt {
        /// The field's path in the model.
        field: &'static str,
        /// The entry's position in its list.
        index: usize,
    },
}

impl core::fmt::Display for ModelError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            ModelError::NonFinite { field, index } => write!(f, "field `{field}` has a non-finite value at index {index}"),
            ModelError::OutOfRange { field } => write!(f, "field `{field}` is out of range"),
            ModelError::OutOfRangeAt { field, index } => write!(f, "field `{field}` is out of range at index {index}"),
            ModelError::Dimension { field, expected, found } => {
                write!(f, "field `{field}` has size {found}, expected {expected}")
            }
        }
    }
}

/// Why a blob was rejected.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DecodeError {
    /// Shorter than header plus trailer, or shorter than the declared payload length.
    Truncated {
        /// Bytes the frame needs.
        needed: usize,
        /// Bytes the blob has.
        got: usize,
    },
    /// Longer than header + declared payload + trailer.
    TrailingBytes {
        /// Bytes the header declares (header + payload + trailer).
        expected: usize,
        /// Bytes the blob has.
        got: usize,
    },
    /// The blob does not open with [`MAGIC`].
    BadMagic,
    /// The format version is outside [`OLDEST_FORMAT_VERSION`]..=[`FORMAT_VERSION`].
    UnsupportedVersion {
        /// The blob's version.
        found: u16,
        /// The newest version this build reads.
        supported: u16,
    },
    /// The stored CRC-32 differs from the one computed over header and payload.
    ChecksumMismatch {
        /// The CRC-32 in the trailer.
        stored: u32,
        /// The CRC-32 of the bytes before the trailer.
        computed: u32,
    },
    /// The payload does not decode as a [`Model`] (postcard error).
    Payload,
    /// The model has more joints than this build holds ([`MAX_JOINTS`]; feature `long-chains`).
    TooManyJoints {
        /// Joints in the blob's model.
        found: usize,
        /// [`MAX_JOINTS`] of this build.
        supported: usize,
    },
    /// The payload decoded but is inconsistent (dimensions, non-finite or out-of-range values).
    Invalid(ModelError),
}

/// Why a model could not be encoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EncodeError {
    /// The output buffer cannot hold the blob.
    BufferTooSmall,
    /// The model fails [`Model::validate`].
    Invalid(ModelError),
}

impl core::fmt::Display for DecodeError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            DecodeError::Truncated { needed, got } => {
                write!(f, "blob truncated: needs {needed} bytes, has {got}")
            }
            DecodeError::TrailingBytes { expected, got } => {
                write!(f, "blob has trailing bytes: expected {expected} bytes, has {got}")
            }
            DecodeError::BadMagic => write!(f, "not a CbD model blob (bad magic)"),
            DecodeError::UnsupportedVersion { found, supported } => {
                write!(f, "blob format version {found} is not supported (this build reads {OLDEST_FORMAT_VERSION} to {supported})")
            }
            DecodeError::ChecksumMismatch { stored, computed } => {
                write!(f, "blob checksum mismatch: stored {stored:#010x}, computed {computed:#010x}")
            }
            DecodeError::Payload => write!(f, "blob payload does not decode"),
            DecodeError::TooManyJoints { found, supported } => write!(
                f,
                "the model has {found} joints; this build holds at most {supported} (build the runtime with the feature `long-chains` for up to 16)"
            ),
            DecodeError::Invalid(e) => write!(f, "blob holds an invalid model: {e}"),
        }
    }
}

impl core::fmt::Display for EncodeError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            EncodeError::BufferTooSmall => write!(f, "output buffer too small for the blob"),
            EncodeError::Invalid(e) => write!(f, "refusing to encode an invalid model: {e}"),
        }
    }
}

#[cfg(feature = "std")]
impl std::error::Error for DecodeError {}
#[cfg(feature = "std")]
impl std::error::Error for EncodeError {}

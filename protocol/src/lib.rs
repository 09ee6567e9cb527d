//! The calibrated-model blob: what the trainer writes and the runtime loads.
//!
//! Frame (all integers little-endian):
//!
//! ```text
//! magic "CBDM" (4) | format version u16 (2) | payload length u32 (4) | payload | CRC-32 (4)
//! ```
//!
//! The payload is a postcard encoding of [`Model`] (format 5: followed by the postcard encoding
//! of its `Option<`[`FieldExpansion`]`>`; format 6: then the DH chain's tool points, a varint count
//! and three f64 per point; format 7: then the noise σ, one little-endian f64; formats 2–4 end
//! after the model). The CRC-32 (ISO-HDLC) covers everything
//! before it. The large arrays (measurement configurations, momenta) are stored as raw
//! little-endian `f64` bytes that the runtime reads in place, so a blob in flash is never copied.
#![no_std]
#![deny(missing_docs)]
#![cfg_attr(not(test), deny(clippy::unwrap_used, clippy::expect_used, clippy::panic, clippy::indexing_slicing))]

#[cfg(feature = "std")]
extern crate std;

mod expansion;
mod f64_slice;
mod limits;
mod model;
mod normalisation;
pub mod paper_rr;
mod physical_effects;
mod tool_point_encoding;
pub mod ur5;
mod validate;

pub use expansion::*;
pub use f64_slice::*;
pub use limits::*;
pub use model::*;
pub use normalisation::*;
pub use physical_effects::*;
pub use validate::ModelError;

/// Four bytes that open every blob.
pub const MAGIC: [u8; 4] = *b"CBDM";
/// Version of the payload layout; bumped on any incompatible change.
/// Format 7 appends the noise σ the calibration assumed ([`Model::noise_sigma`]) after the format-6
/// payload; [`encode`] writes it only for a model that carries one.
/// Format 6 appends the DH chain's tool points ([`DhChain::tool_points`]) after the format-5
/// payload; [`encode`] writes it only for a model that names tool points (older models keep their bytes).
/// Format 5 appends the fields' expansions ([`FieldExpansion`]) after the format-4 payload;
/// format 4 adds the gravity moment effect ([`Effect::GravityMoment`]); formats 2 and 3 have
/// the same layout without it and load unchanged. [`encode`] writes format 4 when a model has no
/// expansion (byte-identical to the encoders before format 5), format 5 when it has one.
pub const FORMAT_VERSION: u16 = 7;
/// The format of a model with tool points and without a noise σ.
pub const FORMAT_WITH_TOOL_POINTS: u16 = 6;
/// The format of a model with an expansion and without tool points.
pub const FORMAT_WITH_EXPANSION: u16 = 5;
/// The format of a model without an expansion.
pub const FORMAT_WITHOUT_EXPANSION: u16 = 4;
/// The oldest format this build reads (format 2 lacks the Hamiltonian momentum laws, formats 2
/// and 3 the gravity moment effect).
pub const OLDEST_FORMAT_VERSION: u16 = 2;
/// Bytes before the payload: magic, version, payload length.
pub const HEADER_LEN: usize = 10;
/// Bytes after the payload: the checksum.
pub const TRAILER_LEN: usize = 4;

const CRC32: crc::Crc<u32> = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC);

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

/// The format [`encode`] writes for `model`: 7 when it carries a noise σ, else 6 when it names tool
/// points, else 5 when it has an expansion, else 4 (so a model of an older format keeps its bytes).
pub fn format_for(model: &Model<'_>) -> u16 {
    if model.noise_sigma.is_some() {
        FORMAT_VERSION
    } else if !model.nominal.tool_points().is_empty() {
        FORMAT_WITH_TOOL_POINTS
    } else if model.expansion.is_some() {
        FORMAT_WITH_EXPANSION
    } else {
        FORMAT_WITHOUT_EXPANSION
    }
}

/// Encodes `model` into `out`, returning the number of bytes written.
/// The model is validated first: an invalid model is never written. Without an expansion the blob
/// is format 4 (the payload is the model), with one format 5 (the model, then `Some(expansion)`);
/// with tool points format 6 (the model, its `Option<expansion>`, then the tool points); with a
/// noise σ format 7 (then σ).
pub fn encode(model: &Model<'_>, out: &mut [u8]) -> Result<usize, EncodeError> {
    model.validate().map_err(EncodeError::Invalid)?;
    if out.len() < HEADER_LEN + TRAILER_LEN {
        return Err(EncodeError::BufferTooSmall);
    }
    // Slicing without indexing, as in `decode`: no panic path.
    let room = out.len() - HEADER_LEN - TRAILER_LEN;
    let payload_len = {
        let body = out.get_mut(HEADER_LEN..HEADER_LEN + room).ok_or(EncodeError::BufferTooSmall)?;
        let mut written = postcard::to_slice(model, &mut *body).map_err(|_| EncodeError::BufferTooSmall)?.len();
        let version = format_for(model);
        if version >= FORMAT_WITH_EXPANSION {
            let tail = body.get_mut(written..).ok_or(EncodeError::BufferTooSmall)?;
            written += postcard::to_slice(&model.expansion, tail).map_err(|_| EncodeError::BufferTooSmall)?.len();
        }
        if version >= FORMAT_WITH_TOOL_POINTS {
            let tail = body.get_mut(written..).ok_or(EncodeError::BufferTooSmall)?;
            written += tool_point_encoding::write(model.nominal.tool_points(), tail).ok_or(EncodeError::BufferTooSmall)?;
        }
        if let (true, Some(sigma)) = (version >= FORMAT_VERSION, model.noise_sigma) {
            let tail = body.get_mut(written..).ok_or(EncodeError::BufferTooSmall)?;
            *tail.first_chunk_mut::<8>().ok_or(EncodeError::BufferTooSmall)? = sigma.to_le_bytes();
            written += 8;
        }
        written
    };
    let payload_end = HEADER_LEN + payload_len;
    let version = format_for(model);
    let (framed, trailer) = out.split_at_mut_checked(payload_end).ok_or(EncodeError::BufferTooSmall)?;
    let header = MAGIC.into_iter().chain(version.to_le_bytes()).chain((payload_len as u32).to_le_bytes());
    for (byte, value) in framed.iter_mut().zip(header) {
        *byte = value;
    }
    let crc = CRC32.checksum(framed);
    *trailer.first_chunk_mut::<TRAILER_LEN>().ok_or(EncodeError::BufferTooSmall)? = crc.to_le_bytes();
    Ok(payload_end + TRAILER_LEN)
}

/// Encodes `model` into a new vector (std only).
#[cfg(feature = "std")]
pub fn encode_to_vec(model: &Model<'_>) -> Result<std::vec::Vec<u8>, EncodeError> {
    let expansion = model.expansion.as_ref().map_or(0, |e| 64 + e.joint_codes.len() + e.task_exponents.len() + e.weights.byte_len());
    let mut buf = std::vec![0u8; 4096 + model.points.byte_len() + model.momenta.byte_len() + expansion];
    let len = encode(model, &mut buf)?;
    buf.truncate(len);
    Ok(buf)
}

/// Checks the frame (magic, version, length, checksum), decodes the payload and validates it.
/// The returned model borrows its arrays from `blob`.
pub fn decode(blob: &[u8]) -> Result<Model<'_>, DecodeError> {
    let min = HEADER_LEN + TRAILER_LEN;
    if blob.len() < min {
        return Err(DecodeError::Truncated { needed: min, got: blob.len() });
    }
    let Some([m0, m1, m2, m3, v0, v1, l0, l1, l2, l3]) = blob.first_chunk::<HEADER_LEN>().copied() else {
        return Err(DecodeError::Truncated { needed: min, got: blob.len() });
    };
    if [m0, m1, m2, m3] != MAGIC {
        return Err(DecodeError::BadMagic);
    }
    let version = u16::from_le_bytes([v0, v1]);
    if !(OLDEST_FORMAT_VERSION..=FORMAT_VERSION).contains(&version) {
        return Err(DecodeError::UnsupportedVersion { found: version, supported: FORMAT_VERSION });
    }
    let payload_len = u32::from_le_bytes([l0, l1, l2, l3]) as usize;
    let total = HEADER_LEN.saturating_add(payload_len).saturating_add(TRAILER_LEN);
    if blob.len() < total {
        return Err(DecodeError::Truncated { needed: total, got: blob.len() });
    }
    if blob.len() > total {
        return Err(DecodeError::TrailingBytes { expected: total, got: blob.len() });
    }
    let payload_end = HEADER_LEN + payload_len;
    // Slicing without indexing: decoding has no panic path (the firmware's panic-never build checks it).
    let (framed, trailer) = blob.split_at_checked(payload_end).ok_or(DecodeError::Truncated { needed: total, got: blob.len() })?;
    let [t0, t1, t2, t3] = *trailer else { return Err(DecodeError::Truncated { needed: total, got: blob.len() }) };
    let stored = u32::from_le_bytes([t0, t1, t2, t3]);
    let computed = CRC32.checksum(framed);
    if stored != computed {
        return Err(DecodeError::ChecksumMismatch { stored, computed });
    }
    let payload = framed.get(HEADER_LEN..).ok_or(DecodeError::Payload)?;
    let (mut model, rest): (Model<'_>, &[u8]) = postcard::take_from_bytes(payload).map_err(|_| payload_error(payload))?;
    let rest = if version >= FORMAT_WITH_EXPANSION {
        // Format 5: the expansion follows the model (`None` allowed, absence not).
        let (expansion, rest): (Option<FieldExpansion<'_>>, &[u8]) = postcard::take_from_bytes(rest).map_err(|_| DecodeError::Payload)?;
        model.expansion = expansion;
        rest
    } else {
        rest
    };
    let rest = if version >= FORMAT_WITH_TOOL_POINTS {
        // Format 6: the tool points follow (an empty list allowed, absence not).
        let (points, rest) = tool_point_encoding::read(rest)?;
        match &mut model.nominal {
            NominalModel::DhChain(chain) => chain.tool_points = points,
            NominalModel::PlanarChain { .. } if points.is_empty() => {}
            NominalModel::PlanarChain { .. } => {
                return Err(DecodeError::Invalid(ModelError::OutOfRange { field: "nominal.tool_points (on a planar chain)" }))
            }
        }
        rest
    } else {
        rest
    };
    let rest = if version >= FORMAT_VERSION {
        // Format 7: the noise σ follows.
        let (sigma, rest) = rest.split_first_chunk::<8>().ok_or(DecodeError::Payload)?;
        model.noise_sigma = Some(f64::from_le_bytes(*sigma));
        rest
    } else {
        rest
    };
    if !rest.is_empty() {
        return Err(DecodeError::Payload);
    }
    if model.momentum_law.first_format() > version {
        // A format-2 blob cannot hold a later law: the bytes were not written by an encoder.
        return Err(DecodeError::Invalid(ModelError::OutOfRange { field: "momentum_law (not in this blob's format version)" }));
    }
    if model.nominal.effects().list.iter().any(|e| e.first_format() > version) {
        // A format-3 blob cannot hold a gravity moment: the bytes were not written by an encoder.
        return Err(DecodeError::Invalid(ModelError::OutOfRange {
            field: "nominal.effects.list.GravityMoment (not in this blob's format version)",
        }));
    }
    model.validate().map_err(DecodeError::Invalid)?;
    Ok(model)
}

#[cfg(test)]
mod tests;
#[cfg(test)]
mod tests_expansion;
#[cfg(test)]
mod tests_tool_points;

/// Why a payload did not decode: a chain longer than this build holds is named (its joint count is
/// the first length in the payload: the nominal model's variant, then the planar lengths' count or
/// the DH convention and the joints' count, all postcard varints); anything else is `Payload`.
// With the feature `long-chains` MAX_JOINTS is MAX_JOINTS_ANY_BUILD: no count is too many.
#[allow(clippy::impossible_comparisons)]
fn payload_error(payload: &[u8]) -> DecodeError {
    fn varint(bytes: &mut core::slice::Iter<'_, u8>) -> Option<usize> {
        let mut value = 0usize;
        for shift in (0..35).step_by(7) {
            let b = *bytes.next()?;
            value |= usize::from(b & 0x7f) << shift;
            if b & 0x80 == 0 {
                return Some(value);
            }
        }
        None
    }
    let mut bytes = payload.iter();
    let found = match varint(&mut bytes) {
        Some(0) => varint(&mut bytes),
        Some(1) => varint(&mut bytes).and_then(|_convention| varint(&mut bytes)),
        _ => None,
    };
    match found {
        Some(found) if found > MAX_JOINTS && found <= MAX_JOINTS_ANY_BUILD => DecodeError::TooManyJoints { found, supported: MAX_JOINTS },
        _ => DecodeError::Payload,
    }
}

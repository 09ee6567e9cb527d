//! The blob's frame: encoding and decoding (see the crate's documentation for the layout).

use crate::error::{DecodeError, EncodeError, ModelError};
use crate::expansion::FieldExpansion;
use crate::format::*;
use crate::limits::{MAX_JOINTS, MAX_JOINTS_ANY_BUILD};
use crate::model::{ConfigurationKernel, Model, NominalModel, Provenance, RowDrift};
use crate::tool_point_encoding;

pub(crate) const CRC32: crc::Crc<u32> = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC);

/// The format [`encode`] writes for `model`: 9 when it has a provenance, else 8 when it has a
/// configuration kernel or a drift, else 7 when it
/// carries a noise σ, else 6 when it names tool points, else 5 when it has an expansion, else 4 (so
/// a model of an older format keeps its bytes).
pub fn format_for(model: &Model<'_>) -> u16 {
    if model.provenance.is_some() {
        FORMAT_VERSION
    } else if model.configuration_kernel.is_some() || model.drift.is_some() {
        FORMAT_WITH_CONFIGURATION_KERNEL
    } else if model.noise_sigma.is_some() {
        FORMAT_WITH_NOISE_SIGMA
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
        if version >= FORMAT_WITH_NOISE_SIGMA {
            // Validated: a format-8 model carries σ (its layout has the slot).
            let sigma =
                model.noise_sigma.ok_or(EncodeError::Invalid(ModelError::OutOfRange { field: "noise_sigma (format 8 needs it)" }))?;
            let tail = body.get_mut(written..).ok_or(EncodeError::BufferTooSmall)?;
            *tail.first_chunk_mut::<8>().ok_or(EncodeError::BufferTooSmall)? = sigma.to_le_bytes();
            written += 8;
        }
        if version >= FORMAT_WITH_CONFIGURATION_KERNEL {
            let tail = body.get_mut(written..).ok_or(EncodeError::BufferTooSmall)?;
            written += postcard::to_slice(&model.configuration_kernel, tail).map_err(|_| EncodeError::BufferTooSmall)?.len();
            let tail = body.get_mut(written..).ok_or(EncodeError::BufferTooSmall)?;
            written += postcard::to_slice(&model.drift, tail).map_err(|_| EncodeError::BufferTooSmall)?.len();
        }
        if version >= FORMAT_VERSION {
            let tail = body.get_mut(written..).ok_or(EncodeError::BufferTooSmall)?;
            written += postcard::to_slice(&model.provenance, tail).map_err(|_| EncodeError::BufferTooSmall)?.len();
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
    let rest = if version >= FORMAT_WITH_NOISE_SIGMA {
        // Format 7: the noise σ follows.
        let (sigma, rest) = rest.split_first_chunk::<8>().ok_or(DecodeError::Payload)?;
        model.noise_sigma = Some(f64::from_le_bytes(*sigma));
        rest
    } else {
        rest
    };
    let rest = if version >= FORMAT_WITH_CONFIGURATION_KERNEL {
        // Format 8: the configuration kernel follows (`None` allowed, absence not).
        let (kernel, rest): (Option<ConfigurationKernel>, &[u8]) = postcard::take_from_bytes(rest).map_err(|_| DecodeError::Payload)?;
        model.configuration_kernel = kernel;
        // Then the drift (`None` allowed, absence not).
        let (drift, rest): (Option<RowDrift>, &[u8]) = postcard::take_from_bytes(rest).map_err(|_| DecodeError::Payload)?;
        model.drift = drift;
        rest
    } else {
        rest
    };
    let rest = if version >= FORMAT_VERSION {
        // Format 9: the provenance follows (`None` allowed, absence not).
        let (provenance, rest): (Option<Provenance>, &[u8]) = postcard::take_from_bytes(rest).map_err(|_| DecodeError::Payload)?;
        model.provenance = provenance;
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

/// Why a payload did not decode: a chain longer than this build holds is named (its joint count is
/// the first length in the payload: the nominal model's variant, then the planar lengths' count or
/// the DH convention and the joints' count, all postcard varints); anything else is `Payload`.
// With the feature `long-chains` MAX_JOINTS is MAX_JOINTS_ANY_BUILD: no count is too many.
#[allow(clippy::impossible_comparisons)]
pub(crate) fn payload_error(payload: &[u8]) -> DecodeError {
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

/// `model` with a synthetic expansion, encoded (std only; the test and benchmark blobs of the
/// firmware check and the cross-crate tests): the joint `codes` and task `exponents` given, and per
/// stage, per function in storage order, weights `scale · draw() / (1 + degree)`, degree the sum of
/// the function's orders (higher orders damped, as a kernel's series is).
#[cfg(feature = "std")]
pub fn encode_with_synthetic_expansion(
    model: &Model<'_>,
    codes: &[u8],
    exponents: &[u8],
    scale: f64,
    mut draw: impl FnMut() -> f64,
) -> Result<std::vec::Vec<u8>, EncodeError> {
    use crate::expansion::code_order;
    use crate::f64_slice::F64Slice;
    let (n, m) = (model.n_joints(), model.task_dim());
    let (r_v, r_w) = (codes.len() / n.max(1), exponents.len() / m.max(1));
    let mut weights = std::vec::Vec::new();
    for _ in 0..model.integrator.stage_count() {
        for function in codes.chunks_exact(n.max(1)) {
            let degree: u32 = function.iter().map(|&c| code_order(c) as u32).sum();
            weights.extend((0..n).map(|_| scale * draw() / (1.0 + degree as f64)));
        }
        for function in exponents.chunks_exact(m.max(1)) {
            let degree: u32 = function.iter().map(|&a| a as u32).sum();
            weights.extend((0..m).map(|_| scale * draw() / (1.0 + degree as f64)));
        }
    }
    let bytes = crate::f64_slice::f64_le_bytes(&weights);
    let mut model = model.clone();
    model.expansion = Some(FieldExpansion {
        tolerance: 1e-9,
        task_radius: 2.0,
        n_joint_features: r_v as u32,
        joint_codes: codes,
        n_task_features: r_w as u32,
        task_exponents: exponents,
        weights: F64Slice::from_le_bytes(&bytes),
    });
    encode_to_vec(&model)
}

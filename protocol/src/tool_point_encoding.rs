//! Format 6: the DH chain's tool points after the format-5 payload — a postcard varint count, then
//! three little-endian f64 per point (what postcard writes for `HVec<[f64; 3], _>`), read by hand so
//! that a count beyond [`MAX_TOOL_POINTS`] is named rather than a bare payload error.

use heapless::Vec as HVec;

use crate::error::{DecodeError, ModelError};
use crate::limits::MAX_TOOL_POINTS;

/// Writes `points` into `out`; the bytes written, or `None` when `out` is too small.
pub(crate) fn write(points: &[[f64; 3]], out: &mut [u8]) -> Option<usize> {
    // The count is at most MAX_TOOL_POINTS < 128: one varint byte.
    let count = u8::try_from(points.len()).ok().filter(|c| *c < 0x80)?;
    let (first, mut rest) = out.split_first_mut()?;
    *first = count;
    for v in points.iter().flatten() {
        let (dst, tail) = rest.split_first_chunk_mut::<8>()?;
        *dst = v.to_le_bytes();
        rest = tail;
    }
    Some(1 + 24 * points.len())
}

/// Reads the tool points from the start of `bytes`; the points and the bytes after them.
pub(crate) fn read(bytes: &[u8]) -> Result<(HVec<[f64; 3], MAX_TOOL_POINTS>, &[u8]), DecodeError> {
    let (&count, mut rest) = bytes.split_first().ok_or(DecodeError::Payload)?;
    if count & 0x80 != 0 || usize::from(count) > MAX_TOOL_POINTS {
        return Err(DecodeError::Invalid(ModelError::Dimension {
            field: "nominal.tool_points (at most MAX_TOOL_POINTS)",
            expected: MAX_TOOL_POINTS,
            found: usize::from(count),
        }));
    }
    let mut points = HVec::new();
    for _ in 0..count {
        let mut point = [0.0; 3];
        for c in point.iter_mut() {
            let (v, tail) = rest.split_first_chunk::<8>().ok_or(DecodeError::Payload)?;
            *c = f64::from_le_bytes(*v);
            rest = tail;
        }
        points.push(point).map_err(|_| DecodeError::Payload)?;
    }
    Ok((points, rest))
}

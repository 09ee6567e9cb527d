//! A borrowed array of little-endian `f64` (the blob's large arrays), read in place.

use serde::{Deserialize, Deserializer, Serialize, Serializer};

/// A borrowed array of little-endian `f64`, read in place (no alignment needed, no copy).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct F64Slice<'a>(&'a [u8]);

impl<'a> F64Slice<'a> {
    /// Wraps little-endian bytes; the length must be a multiple of 8 (checked on validation).
    pub const fn from_le_bytes(bytes: &'a [u8]) -> Self {
        F64Slice(bytes)
    }
    /// The number of whole values.
    pub fn len(&self) -> usize {
        self.0.len() / 8
    }
    /// Whether there is no whole value.
    pub fn is_empty(&self) -> bool {
        self.0.len() < 8
    }
    /// The length in bytes.
    pub fn byte_len(&self) -> usize {
        self.0.len()
    }
    /// The little-endian bytes.
    pub fn bytes(&self) -> &'a [u8] {
        self.0
    }
    /// The `i`-th value, or `None` past the end.
    #[inline]
    pub fn get(&self, i: usize) -> Option<f64> {
        let b = self.0.get(i * 8..i * 8 + 8)?;
        let mut a = [0u8; 8];
        for (d, s) in a.iter_mut().zip(b) {
            *d = *s;
        }
        Some(f64::from_le_bytes(a))
    }
    /// The values in order (a trailing partial value is skipped).
    pub fn iter(&self) -> impl Iterator<Item = f64> + 'a {
        self.0.chunks_exact(8).map(|c| {
            let mut a = [0u8; 8];
            for (d, s) in a.iter_mut().zip(c) {
                *d = *s;
            }
            f64::from_le_bytes(a)
        })
    }
}

impl Serialize for F64Slice<'_> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_bytes(self.0)
    }
}

impl<'de: 'a, 'a> Deserialize<'de> for F64Slice<'a> {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        <&'de [u8]>::deserialize(d).map(F64Slice)
    }
}

/// Little-endian bytes of `values` (std only), for building a [`F64Slice`].
#[cfg(feature = "std")]
pub fn f64_le_bytes(values: &[f64]) -> std::vec::Vec<u8> {
    values.iter().flat_map(|v| v.to_le_bytes()).collect()
}

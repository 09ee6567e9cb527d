//! Fixed-length arrays read exactly: serde's `[T; N]` takes the first N entries of a TOML array
//! and ignores the rest (`translation = [0, 0, 31, 99]` read as [0, 0, 31]), so every fixed-length
//! field of a model file goes through [`Exactly`], which refuses any other length — too short or
//! too long — with the parser's position of the array.

use serde::de::{self, Deserialize, Deserializer, IgnoredAny, SeqAccess, Visitor};
use std::fmt;
use std::marker::PhantomData;

/// An array of exactly `N` entries.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Exactly<T, const N: usize>(pub [T; N]);

impl<'de, T: Deserialize<'de>, const N: usize> Deserialize<'de> for Exactly<T, N> {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct Entries<T, const N: usize>(PhantomData<T>);
        impl<'de, T: Deserialize<'de>, const N: usize> Visitor<'de> for Entries<T, N> {
            type Value = Exactly<T, N>;
            fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                write!(f, "an array of exactly {N} entries")
            }
            fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Self::Value, A::Error> {
                let mut entries = Vec::with_capacity(N);
                while entries.len() < N {
                    match seq.next_element::<T>()? {
                        Some(v) => entries.push(v),
                        None => return Err(de::Error::invalid_length(entries.len(), &self)),
                    }
                }
                // Count what is left whatever its type: the message gives the whole length.
                let mut extra = 0;
                while seq.next_element::<IgnoredAny>()?.is_some() {
                    extra += 1;
                }
                if extra > 0 {
                    return Err(de::Error::invalid_length(N + extra, &self));
                }
                Ok(Exactly(entries.try_into().unwrap_or_else(|_| unreachable!("N entries read"))))
            }
        }
        d.deserialize_seq(Entries::<T, N>(PhantomData))
    }
}

/// An optional array of exactly N entries (with `#[serde(default)]`).
pub fn optional<'de, D: Deserializer<'de>, T: Deserialize<'de>, const N: usize>(d: D) -> Result<Option<[T; N]>, D::Error> {
    Option::<Exactly<T, N>>::deserialize(d).map(|o| o.map(|e| e.0))
}

/// An optional R × C matrix: exactly R rows of exactly C entries (with `#[serde(default)]`).
pub fn optional_matrix<'de, D: Deserializer<'de>, const R: usize, const C: usize>(d: D) -> Result<Option<[[f64; C]; R]>, D::Error> {
    Option::<Exactly<Exactly<f64, C>, R>>::deserialize(d).map(|o| o.map(|rows| rows.0.map(|row| row.0)))
}

/// An optional list of arrays of exactly N entries each (with `#[serde(default)]`).
pub fn optional_list<'de, D: Deserializer<'de>, T: Deserialize<'de>, const N: usize>(d: D) -> Result<Option<Vec<[T; N]>>, D::Error> {
    Option::<Vec<Exactly<T, N>>>::deserialize(d).map(|o| o.map(|v| v.into_iter().map(|e| e.0).collect()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, serde::Deserialize)]
    struct Fields {
        #[serde(default, deserialize_with = "optional")]
        v: Option<[f64; 3]>,
        #[serde(default, deserialize_with = "optional_matrix")]
        m: Option<[[f64; 2]; 2]>,
        #[serde(default, deserialize_with = "optional_list")]
        l: Option<Vec<[f64; 2]>>,
    }

    fn read(text: &str) -> Result<Fields, String> {
        toml::from_str(text).map_err(|e| e.message().to_string())
    }

    /// Issue 39 case 5: serde's `[f64; 3]` read `[0, 0, 31, 99]` as [0, 0, 31]; now every length
    /// but N is refused, extra entries of any type (NaN, a string) counted.
    #[test]
    fn only_the_exact_length_is_read() {
        assert_eq!(read("v = [1, 2, 3]\nm = [[1, 2], [3, 4]]\nl = [[1, 2]]").unwrap().m, Some([[1.0, 2.0], [3.0, 4.0]]));
        assert_eq!(read("").unwrap().v, None);
        assert_eq!(read("l = [[1, 2], [3, 4]]").unwrap().l, Some(vec![[1.0, 2.0], [3.0, 4.0]]));
        for (text, needle) in [
            ("v = [0, 0, 31, 99]", "invalid length 4, expected an array of exactly 3 entries"),
            ("v = [0, 0, 31, nan]", "invalid length 4"),
            ("v = [0, 0, 31, \"x\", 5]", "invalid length 5"),
            ("v = [0, 0]", "invalid length 2"),
            ("m = [[1, 2], [3, 4], [5, 6]]", "invalid length 3, expected an array of exactly 2"),
            ("m = [[1, 2], [3, 4, 5]]", "invalid length 3, expected an array of exactly 2"),
            ("l = [[1, 2], [3, 4, 5]]", "invalid length 3"),
        ] {
            let e = read(text).unwrap_err();
            assert!(e.contains(needle), "{text}: {e}");
        }
    }
}

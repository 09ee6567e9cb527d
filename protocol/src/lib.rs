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

mod codec;
mod error;
mod expansion;
mod f64_slice;
mod format;
mod limits;
mod model;
mod normalisation;
pub mod paper_rr;
mod physical_effects;
mod tool_point_encoding;
pub mod ur5;
mod validate;

pub use codec::*;
pub use error::*;
pub use expansion::*;
pub use f64_slice::*;
pub use format::*;
pub use limits::*;
pub use model::*;
pub use normalisation::*;
pub use physical_effects::*;

#[cfg(test)]
mod tests;
#[cfg(test)]
mod tests_expansion;
#[cfg(test)]
mod tests_tool_points;

//! The peers Calibration by Diffeomorphisms is compared with.

pub mod commanded;
pub mod compare;
pub mod krr;

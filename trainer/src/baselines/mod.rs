//! The peers Calibration by Diffeomorphisms is compared with.

pub mod krr;

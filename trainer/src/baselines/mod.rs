//! The peers Calibration by Diffeomorphisms is compared with.

pub mod krr;
pub mod dh_calibration;
pub mod compare;

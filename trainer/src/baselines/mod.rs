//! The peers Calibration by Diffeomorphisms is compared with.

pub mod dh_calibration;
pub mod kernel_ridge;

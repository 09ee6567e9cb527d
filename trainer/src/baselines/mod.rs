//! The peers Calibration by Diffeomorphisms is compared with.

pub mod kernel_ridge;

//! Error statistics and tables.

pub mod checks;
pub mod html;
pub mod noise_floor;
pub mod plots;
pub mod progress;
pub mod stats;

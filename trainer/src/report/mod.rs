//! Error statistics and tables.

pub mod html;
pub mod plots;
pub mod progress;
pub mod stats;

//! Error statistics and tables.

pub mod stats;
pub mod html;
pub mod plots;
pub mod progress;

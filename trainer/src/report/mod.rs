//! Error statistics and tables.

pub mod stats;

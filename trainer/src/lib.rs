//! Offline trainer for Calibration by Diffeomorphisms, laid out by pipeline stage:
//! data import → nominal models → kernels → flow (primal + tangent) → solver → baselines →
//! diagnosis → planning (where to measure next) → reports → CLI.

pub mod baselines;
pub mod calibrate;
pub mod cli;
pub mod data;
pub mod diagnose;
pub mod error;
pub mod evaluation;
pub mod expansion;
pub mod flow;
pub mod io;
pub mod kernels;
pub mod memory;
pub mod nominal;
pub mod parametric;
pub mod plan;
pub mod predict;
pub mod report;
pub mod simulate;
pub mod solver;
pub mod workers;

pub use error::{Error, Result};

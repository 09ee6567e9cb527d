//! Offline trainer for Calibration by Diffeomorphisms, laid out by pipeline stage:
//! data import → nominal models → kernels → flow (primal + tangent) → solver → baselines →
//! diagnosis → reports → CLI.

pub mod data;
pub mod nominal;
pub mod simulate;
pub mod kernels;
pub mod flow;
pub mod solver;
pub mod predict;
pub mod baselines;
pub mod report;
pub mod cli;

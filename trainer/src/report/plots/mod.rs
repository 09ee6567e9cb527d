//! Figures for `--plots DIR`: every function writes the same figure as PNG and SVG into `dir`
//! (created if missing) and returns the paths it wrote.
//!
//! Text is drawn with DejaVu Sans embedded from the `dejavu` crate, so PNGs need no system fonts;
//! SVGs name the `sans-serif` family and let the viewer pick it.
//!
//! Lengths are in whatever unit the caller names (`unit`, e.g. "length units", "mm"); joint labels
//! are taken as given, so include their unit (e.g. "q1 (rad)").
//!
//! One file per figure; what they share (fonts, rendering, colours, labels, legend) is in `chart`.

mod chart;
mod comparison;
mod convergence;
mod demo;
mod heatmaps;
mod histograms;
mod history;
mod residuals;
mod workspace;

pub use crate::report::stats::position_errors;
pub use chart::viridis;
pub use comparison::{method_comparison, COMPARISON_WIDTH};
pub use convergence::{convergence, convergence_svg, CONVERGENCE_SIZE};
pub use demo::{demo_figures, DemoPlotInputs, PlanarMap};
pub use heatmaps::{error_heatmaps, joint_grid, HEATMAP_SIZE};
pub use histograms::{error_histograms, HISTOGRAM_SIZE};
pub use history::{check_history, check_history_svg, HISTORY_SIZE};
pub use residuals::{residual_vs_joint, EffectCurve, RESIDUAL_WIDTH};
pub use workspace::{workspace_grid, WORKSPACE_SIZE};

#[cfg(test)]
mod tests;

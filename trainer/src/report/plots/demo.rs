//! Every figure of `cbd demo` at once.

use super::convergence::convergence;
use super::heatmaps::{error_heatmaps, joint_grid};
use super::histograms::error_histograms;
use super::workspace::workspace_grid;
use std::path::{Path, PathBuf};

/// Batch kinematics of a planar arm: joints row-major (2 per row) → positions row-major (2 per row).
pub type PlanarMap<'a> = &'a dyn Fn(&[f64]) -> crate::Result<Vec<f64>>;

/// What [`demo_figures`] needs from `cbd demo` (planar two-joint arms).
pub struct DemoPlotInputs<'a> {
    /// Nominal, real (simulated) and calibrated forward kinematics.
    pub nominal: PlanarMap<'a>,
    pub real: PlanarMap<'a>,
    pub calibrated: PlanarMap<'a>,
    /// Axis labels of the two joints, with unit, e.g. ["q1 (rad)", "q2 (rad)"].
    pub joint_labels: [&'a str; 2],
    /// Position errors on the test set before (nominal) and after calibration.
    pub test_before: &'a [f64],
    pub test_after: &'a [f64],
    /// Solver log: (iteration, energy, train_rms).
    pub fit_log: &'a [(usize, f64, f64)],
    /// Length unit, e.g. "length units".
    pub unit: &'a str,
    /// Heatmap resolution per joint (e.g. 64) and workspace grid lines per joint (e.g. 16).
    pub heatmap_per_axis: usize,
    pub workspace_per_axis: usize,
}

fn planar_errors(a: &[f64], b: &[f64]) -> Vec<f64> {
    a.chunks_exact(2).zip(b.chunks_exact(2)).map(|(p, q)| ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2)).sqrt()).collect()
}

fn as_points(v: &[f64]) -> Vec<[f64; 2]> {
    v.chunks_exact(2).map(|p| [p[0], p[1]]).collect()
}

/// Every figure of the RR demo: heatmaps over a `heatmap_per_axis`² grid of [0, 2π)², the
/// workspace grid, the test-set histogram and the convergence plot. Returns the files written.
pub fn demo_figures(dir: &Path, inputs: &DemoPlotInputs) -> crate::Result<Vec<PathBuf>> {
    let two_pi = 2.0 * std::f64::consts::PI;
    let mut written = Vec::new();

    let n = inputs.heatmap_per_axis.max(2);
    let grid = joint_grid(n, 0.0, two_pi);
    let joints: Vec<f64> = grid.iter().flat_map(|&(a, b)| [a, b]).collect();
    let real = (inputs.real)(&joints)?;
    let before = planar_errors(&(inputs.nominal)(&joints)?, &real);
    let after = planar_errors(&(inputs.calibrated)(&joints)?, &real);
    let [la, lb] = inputs.joint_labels;
    written.extend(error_heatmaps(dir, la, lb, &grid, &before, &after, n, inputs.unit)?);

    let n = inputs.workspace_per_axis.max(2);
    let joints: Vec<f64> = joint_grid(n, 0.0, two_pi).iter().flat_map(|&(a, b)| [a, b]).collect();
    let nominal = as_points(&(inputs.nominal)(&joints)?);
    let real = as_points(&(inputs.real)(&joints)?);
    let calibrated = as_points(&(inputs.calibrated)(&joints)?);
    written.extend(workspace_grid(dir, &nominal, &real, &calibrated, n, true, inputs.unit)?);

    written.extend(error_histograms(dir, inputs.test_before, inputs.test_after, inputs.unit)?);
    if !inputs.fit_log.is_empty() {
        written.extend(convergence(dir, inputs.fit_log, inputs.unit)?);
    }
    Ok(written)
}

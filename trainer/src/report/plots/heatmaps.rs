//! Error heatmaps over the joint torus, before and after calibration (paper Figs. 6, 7, 10, 11).

use super::chart::*;
use crate::report::stats::median;
use plotters::coord::Shift;
use plotters::prelude::*;
use std::path::{Path, PathBuf};

/// Pixel size of every PNG written by [`error_heatmaps`].
pub const HEATMAP_SIZE: (u32, u32) = (1500, 640);

struct Heatmaps<'a> {
    joint_a: &'a str,
    joint_b: &'a str,
    cells: usize,
    range_a: (f64, f64),
    range_b: (f64, f64),
    /// cells × cells log10 errors (NaN where empty), index [ia * cells + ib].
    before: Vec<f64>,
    after: Vec<f64>,
    scale: (f64, f64),
    median_before: f64,
    median_after: f64,
    unit: &'a str,
}

/// Averages log10 errors of points into `cells × cells` bins centred on a regular lattice from
/// the smallest to the largest coordinate (a regular grid of `cells` per axis gets one point a bin).
pub(super) fn bin_log_errors(grid: &[(f64, f64)], errors: &[f64], cells: usize, ra: (f64, f64), rb: (f64, f64)) -> Vec<f64> {
    let mut sum = vec![0.0; cells * cells];
    let mut count = vec![0usize; cells * cells];
    let index = |v: f64, (lo, hi): (f64, f64)| -> usize {
        if cells == 1 || hi <= lo {
            return 0;
        }
        (((v - lo) / (hi - lo) * (cells - 1) as f64).round().max(0.0) as usize).min(cells - 1)
    };
    for (&(a, b), &e) in grid.iter().zip(errors) {
        let l = log_err(e);
        if !l.is_finite() || !a.is_finite() || !b.is_finite() {
            continue;
        }
        let k = index(a, ra) * cells + index(b, rb);
        sum[k] += l;
        count[k] += 1;
    }
    sum.iter().zip(&count).map(|(s, &c)| if c == 0 { f64::NAN } else { s / c as f64 }).collect()
}

impl Heatmaps<'_> {
    fn cell_size(&self, (lo, hi): (f64, f64)) -> f64 {
        if self.cells <= 1 || hi <= lo {
            1.0
        } else {
            (hi - lo) / (self.cells - 1) as f64
        }
    }

    fn panel<DB: DrawingBackend>(&self, area: &DrawingArea<DB, Shift>, title: &str, values: &[f64]) -> crate::Result<()> {
        let (da, db) = (self.cell_size(self.range_a), self.cell_size(self.range_b));
        let xr = (self.range_a.0 - da / 2.0)..(self.range_a.1 + da / 2.0);
        let yr = (self.range_b.0 - db / 2.0)..(self.range_b.1 + db / 2.0);
        let mut chart = ChartBuilder::on(area)
            .caption(title, (FONT, 24))
            .margin(12)
            .x_label_area_size(55)
            .y_label_area_size(70)
            .build_cartesian_2d(xr, yr)
            .map_err(pe)?;
        chart
            .configure_mesh()
            .disable_mesh()
            .x_desc(self.joint_a)
            .y_desc(self.joint_b)
            .axis_desc_style((FONT, 20))
            .label_style((FONT, 16))
            .x_label_formatter(&|v| format!("{v:.1}"))
            .y_label_formatter(&|v| format!("{v:.1}"))
            .draw()
            .map_err(pe)?;
        let (lo, hi) = self.scale;
        let grey = RGBColor(220, 220, 220);
        chart
            .draw_series((0..self.cells * self.cells).map(|k| {
                let (ia, ib) = (k / self.cells, k % self.cells);
                let a = self.range_a.0 + ia as f64 * da;
                let b = self.range_b.0 + ib as f64 * db;
                let v = values[k];
                let color = if v.is_finite() { viridis((v - lo) / (hi - lo)) } else { grey };
                Rectangle::new([(a - da / 2.0, b - db / 2.0), (a + da / 2.0, b + db / 2.0)], color.filled())
            }))
            .map_err(pe)?;
        Ok(())
    }

    fn colour_bar<DB: DrawingBackend>(&self, area: &DrawingArea<DB, Shift>) -> crate::Result<()> {
        let (lo, hi) = self.scale;
        let mut chart = ChartBuilder::on(area)
            .caption(" ", (FONT, 24))
            .margin(12)
            .margin_left(4)
            .x_label_area_size(55)
            .y_label_area_size(95)
            .build_cartesian_2d(0.0..1.0, lo..hi)
            .map_err(pe)?;
        chart
            .configure_mesh()
            .disable_mesh()
            .disable_x_axis()
            .y_desc(format!("log10 position error ({})", self.unit))
            .axis_desc_style((FONT, 20))
            .label_style((FONT, 16))
            .y_label_formatter(&|v| format!("{v:.1}"))
            .draw()
            .map_err(pe)?;
        let steps = 200;
        chart
            .draw_series((0..steps).map(|i| {
                let y0 = lo + (hi - lo) * i as f64 / steps as f64;
                let y1 = lo + (hi - lo) * (i + 1) as f64 / steps as f64;
                Rectangle::new([(0.0, y0), (1.0, y1)], viridis((i as f64 + 0.5) / steps as f64).filled())
            }))
            .map_err(pe)?;
        Ok(())
    }
}

impl Figure for Heatmaps<'_> {
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> crate::Result<()> {
        let title = format!(
            "log10 position error over the ({}, {}) grid — median {} → {} {}",
            bare_name(self.joint_a),
            bare_name(self.joint_b),
            fmt_sci(10f64.powf(self.median_before)),
            fmt_sci(10f64.powf(self.median_after)),
            self.unit
        );
        let root = root.titled(&title, (FONT, 28)).map_err(pe)?;
        let w = root.dim_in_pixel().0 as i32;
        let bar_w = 190;
        let panel_w = (w - bar_w) / 2;
        let areas = root.split_by_breakpoints([panel_w, 2 * panel_w], [] as [i32; 0]);
        self.panel(&areas[0], "Before calibration (nominal model)", &self.before)?;
        self.panel(&areas[1], "After calibration", &self.after)?;
        self.colour_bar(&areas[2])
    }
}

/// log10 position error over a grid of two joints, before and after calibration, side by side on
/// one shared colour scale with a colour bar (paper Figs. 6, 7, 10, 11). Writes
/// `error_heatmaps.png` ([`HEATMAP_SIZE`]) and `error_heatmaps.svg`.
///
/// `grid[i]` is the (joint a, joint b) configuration where `before[i]` / `after[i]` were measured
/// (position error norms, in `unit`). The points are binned into `per_axis × per_axis` cells
/// spanning their range: a regular grid with `per_axis` values per joint (any order) gets one
/// point per cell; scattered points are averaged in log space, empty cells are grey.
/// `joint_a` / `joint_b` are axis labels including the unit, e.g. "q1 (rad)".
#[allow(clippy::too_many_arguments)]
pub fn error_heatmaps(
    dir: &Path,
    joint_a: &str,
    joint_b: &str,
    grid: &[(f64, f64)],
    before: &[f64],
    after: &[f64],
    per_axis: usize,
    unit: &str,
) -> crate::Result<Vec<PathBuf>> {
    if grid.is_empty() || grid.len() != before.len() || grid.len() != after.len() {
        return Err(crate::Error::Plot(format!(
            "heatmaps: {} grid points but {} errors before and {} after calibration",
            grid.len(),
            before.len(),
            after.len()
        )));
    }
    if per_axis == 0 {
        return Err(crate::Error::Plot("heatmaps: per_axis must be at least 1".into()));
    }
    let range_a = finite_range(grid.iter().map(|p| &p.0)).ok_or_else(|| crate::Error::Plot("heatmaps: no finite joint values".into()))?;
    let range_b = finite_range(grid.iter().map(|p| &p.1)).ok_or_else(|| crate::Error::Plot("heatmaps: no finite joint values".into()))?;
    let before_bins = bin_log_errors(grid, before, per_axis, range_a, range_b);
    let after_bins = bin_log_errors(grid, after, per_axis, range_a, range_b);
    let (lo, hi) =
        finite_range(before_bins.iter().chain(&after_bins)).ok_or_else(|| crate::Error::Plot("heatmaps: no finite errors".into()))?;
    let logs_before: Vec<f64> = before.iter().map(|&e| log_err(e)).collect();
    let logs_after: Vec<f64> = after.iter().map(|&e| log_err(e)).collect();
    let fig = Heatmaps {
        joint_a,
        joint_b,
        cells: per_axis,
        range_a,
        range_b,
        before: before_bins,
        after: after_bins,
        scale: (lo.floor().min(lo), hi.ceil().max(hi)),
        median_before: median(&logs_before),
        median_after: median(&logs_after),
        unit,
    };
    render(dir, "error_heatmaps", HEATMAP_SIZE, &fig)
}

/// A regular `per_axis × per_axis` grid over [lo, hi)² (upper end excluded, as on the torus),
/// first joint varying slowest — the layout [`error_heatmaps`] and [`workspace_grid`] expect.
pub fn joint_grid(per_axis: usize, lo: f64, hi: f64) -> Vec<(f64, f64)> {
    let step = (hi - lo) / per_axis.max(1) as f64;
    (0..per_axis * per_axis).map(|k| (lo + (k / per_axis) as f64 * step, lo + (k % per_axis) as f64 * step)).collect()
}

//! Figures for `--plots DIR`: every function writes the same figure as PNG and SVG into `dir`
//! (created if missing) and returns the paths it wrote.
//!
//! Text is drawn with DejaVu Sans embedded from the `dejavu` crate, so PNGs need no system fonts;
//! SVGs name the `sans-serif` family and let the viewer pick it.
//!
//! Lengths are in whatever unit the caller names (`unit`, e.g. "length units", "mm"); joint labels
//! are taken as given, so include their unit (e.g. "q1 (rad)").

use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use std::path::{Path, PathBuf};

/// Pixel size of every PNG written by [`error_heatmaps`].
pub const HEATMAP_SIZE: (u32, u32) = (1500, 640);
/// Pixel size of [`workspace_grid`].
pub const WORKSPACE_SIZE: (u32, u32) = (1400, 720);
/// Pixel size of [`error_histograms`].
pub const HISTOGRAM_SIZE: (u32, u32) = (1100, 640);
/// Pixel size of [`convergence`].
pub const CONVERGENCE_SIZE: (u32, u32) = (1100, 560);
/// Width of [`method_comparison`]; its height is 150 + 70 per method.
pub const COMPARISON_WIDTH: u32 = 1100;
/// Width of [`residual_vs_joint`]; its height is 420 per row of (up to) two joints.
pub const RESIDUAL_WIDTH: u32 = 1400;

const FONT: &str = "sans-serif";
/// Errors below this are drawn as this (log10 of an exact zero).
const ERROR_FLOOR: f64 = 1e-16;

/// Registers DejaVu Sans for the bitmap backend (idempotent).
fn ensure_font() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        // Both are valid TrueType files shipped inside the crate; a failure leaves text undrawn
        // in PNGs but never fails a plot.
        let _ = plotters::style::register_font(FONT, FontStyle::Normal, dejavu::sans::regular());
        let _ = plotters::style::register_font(FONT, FontStyle::Bold, dejavu::sans::bold());
    });
}

fn pe<E: std::fmt::Display>(e: E) -> String {
    format!("plot: {e}")
}

/// One figure, drawable on any backend.
trait Figure {
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), String>;
}

/// Draws `fig` to `dir/stem.png` and `dir/stem.svg`.
fn render<F: Figure>(dir: &Path, stem: &str, size: (u32, u32), fig: &F) -> Result<Vec<PathBuf>, String> {
    ensure_font();
    std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let png = dir.join(format!("{stem}.png"));
    let svg = dir.join(format!("{stem}.svg"));
    {
        let root = BitMapBackend::new(&png, size).into_drawing_area();
        root.fill(&WHITE).map_err(pe)?;
        fig.draw(&root).map_err(|e| format!("{}: {e}", png.display()))?;
        root.present().map_err(|e| format!("{}: {e}", png.display()))?;
    }
    {
        let root = SVGBackend::new(&svg, size).into_drawing_area();
        root.fill(&WHITE).map_err(pe)?;
        fig.draw(&root).map_err(|e| format!("{}: {e}", svg.display()))?;
        root.present().map_err(|e| format!("{}: {e}", svg.display()))?;
    }
    Ok(vec![png, svg])
}

/// Draws `fig` as an SVG document in memory (for inline use in HTML).
fn render_svg_string<F: Figure>(size: (u32, u32), fig: &F) -> Result<String, String> {
    ensure_font();
    let mut buf = String::new();
    {
        let root = SVGBackend::with_string(&mut buf, size).into_drawing_area();
        root.fill(&WHITE).map_err(pe)?;
        fig.draw(&root)?;
        root.present().map_err(pe)?;
    }
    Ok(buf)
}

fn log_err(e: f64) -> f64 {
    if e.is_nan() {
        f64::NAN
    } else {
        e.max(ERROR_FLOOR).log10()
    }
}

/// Median of finite values (NaN when there are none).
fn median(values: &[f64]) -> f64 {
    let mut v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(|a, b| a.total_cmp(b));
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

/// Linear-interpolated quantile of sorted finite values.
fn quantile(sorted: &[f64], p: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let pos = p * (sorted.len() - 1) as f64;
    let lo = pos.floor() as usize;
    let hi = pos.ceil() as usize;
    sorted[lo] + (sorted[hi] - sorted[lo]) * (pos - lo as f64)
}

/// Range of finite values, widened when degenerate; `None` when there are none.
fn finite_range<'a>(values: impl IntoIterator<Item = &'a f64>) -> Option<(f64, f64)> {
    let mut lo = f64::INFINITY;
    let mut hi = f64::NEG_INFINITY;
    for &v in values {
        if v.is_finite() {
            lo = lo.min(v);
            hi = hi.max(v);
        }
    }
    if !lo.is_finite() {
        return None;
    }
    if hi - lo < 1e-12 {
        let pad = if lo.abs() > 1e-12 { lo.abs() * 0.05 } else { 0.5 };
        return Some((lo - pad, hi + pad));
    }
    Some((lo, hi))
}

/// The viridis colour map at t ∈ [0, 1] (piecewise linear through 9 anchors).
pub fn viridis(t: f64) -> RGBColor {
    const ANCHORS: [(u8, u8, u8); 9] = [
        (68, 1, 84),
        (71, 44, 122),
        (59, 81, 139),
        (44, 113, 142),
        (33, 144, 141),
        (39, 173, 129),
        (92, 200, 99),
        (170, 220, 50),
        (253, 231, 37),
    ];
    let t = if t.is_finite() { t.clamp(0.0, 1.0) } else { 0.0 };
    let x = t * (ANCHORS.len() - 1) as f64;
    let i = (x.floor() as usize).min(ANCHORS.len() - 2);
    let f = x - i as f64;
    let lerp = |a: u8, b: u8| (a as f64 + (b as f64 - a as f64) * f).round() as u8;
    let (a, b) = (ANCHORS[i], ANCHORS[i + 1]);
    RGBColor(lerp(a.0, b.0), lerp(a.1, b.1), lerp(a.2, b.2))
}

/// "q1 (rad)" → "q1".
fn bare_name(label: &str) -> &str {
    label.split(" (").next().unwrap_or(label).trim()
}

/// A tick label for a linear axis whose values span about `scale`.
fn linear_label(v: f64, scale: f64) -> String {
    if v.abs() < 1e-9 * scale.abs().max(f64::MIN_POSITIVE) {
        return "0".into();
    }
    if (1e-3..1e4).contains(&scale.abs()) {
        let digits = (2.0 - scale.abs().log10().floor()).clamp(0.0, 6.0) as usize;
        format!("{v:.digits$}")
    } else {
        format!("{v:.1e}")
    }
}

fn fmt_sci(v: f64) -> String {
    if !v.is_finite() {
        return "n/a".into();
    }
    format!("{v:.2e}")
}

/// The tick label of a log10 axis value: 1e-2 at whole exponents, 3e-3 between them.
fn pow10_label(v: &f64) -> String {
    if (v - v.round()).abs() < 1e-9 {
        format!("1e{}", v.round() as i64)
    } else {
        format!("{:.0e}", 10f64.powf(*v))
    }
}

// ---------------------------------------------------------------------------------------------
// Heatmaps (paper Figs. 6, 7, 10, 11)
// ---------------------------------------------------------------------------------------------

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
fn bin_log_errors(grid: &[(f64, f64)], errors: &[f64], cells: usize, ra: (f64, f64), rb: (f64, f64)) -> Vec<f64> {
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

    fn panel<DB: DrawingBackend>(&self, area: &DrawingArea<DB, Shift>, title: &str, values: &[f64]) -> Result<(), String> {
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

    fn colour_bar<DB: DrawingBackend>(&self, area: &DrawingArea<DB, Shift>) -> Result<(), String> {
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
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), String> {
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
) -> Result<Vec<PathBuf>, String> {
    if grid.is_empty() || grid.len() != before.len() || grid.len() != after.len() {
        return Err(format!(
            "heatmaps: {} grid points but {} errors before and {} after calibration",
            grid.len(),
            before.len(),
            after.len()
        ));
    }
    if per_axis == 0 {
        return Err("heatmaps: per_axis must be at least 1".into());
    }
    let range_a = finite_range(grid.iter().map(|p| &p.0)).ok_or("heatmaps: no finite joint values")?;
    let range_b = finite_range(grid.iter().map(|p| &p.1)).ok_or("heatmaps: no finite joint values")?;
    let before_bins = bin_log_errors(grid, before, per_axis, range_a, range_b);
    let after_bins = bin_log_errors(grid, after, per_axis, range_a, range_b);
    let (lo, hi) = finite_range(before_bins.iter().chain(&after_bins)).ok_or("heatmaps: no finite errors")?;
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

// ---------------------------------------------------------------------------------------------
// Workspace grid (paper Figs. 8, 9)
// ---------------------------------------------------------------------------------------------

struct Workspace<'a> {
    nominal: &'a [[f64; 2]],
    real: &'a [[f64; 2]],
    calibrated: &'a [[f64; 2]],
    per_axis: usize,
    periodic: bool,
    unit: &'a str,
}

impl Workspace<'_> {
    /// The grid lines: for each value of one joint, the polyline over the other.
    fn lines(&self, pts: &[[f64; 2]]) -> Vec<Vec<(f64, f64)>> {
        let n = self.per_axis;
        let at = |i: usize, j: usize| {
            let p = pts[i * n + j];
            (p[0], p[1])
        };
        let mut out = Vec::with_capacity(2 * n);
        for i in 0..n {
            let mut l: Vec<(f64, f64)> = (0..n).map(|j| at(i, j)).collect();
            if self.periodic {
                l.push(at(i, 0));
            }
            out.push(l);
        }
        for j in 0..n {
            let mut l: Vec<(f64, f64)> = (0..n).map(|i| at(i, j)).collect();
            if self.periodic {
                l.push(at(0, j));
            }
            out.push(l);
        }
        out
    }

    fn panel<DB: DrawingBackend>(
        &self,
        area: &DrawingArea<DB, Shift>,
        title: &str,
        ((x0, x1), (y0, y1)): ((f64, f64), (f64, f64)),
        model: (&[[f64; 2]], RGBColor, &str),
    ) -> Result<(), String> {
        let area = area.titled(title, (FONT, 24)).map_err(pe)?;
        let (margin, xlab, ylab) = (14, 55, 75);
        // Equal axis scales: fit the data box (plus legend room on top) into the plotting area,
        // then widen whichever range has room to spare.
        let (w, h) = area.dim_in_pixel();
        let pw = (w as f64 - 2.0 * margin as f64 - ylab as f64).max(10.0);
        let ph = (h as f64 - 2.0 * margin as f64 - xlab as f64).max(10.0);
        let (dx, dy) = (x1 - x0, (y1 - y0) * 1.22);
        let per_px = (dx / pw).max(dy / ph);
        let (cx, half_x) = (0.5 * (x0 + x1), 0.5 * per_px * pw);
        let top = y0 + per_px * ph;
        let mut chart = ChartBuilder::on(&area)
            .margin(margin)
            .x_label_area_size(xlab)
            .y_label_area_size(ylab)
            .build_cartesian_2d((cx - half_x)..(cx + half_x), y0..top)
            .map_err(pe)?;
        chart
            .configure_mesh()
            .light_line_style(RGBColor(235, 235, 235))
            .bold_line_style(RGBColor(215, 215, 215))
            .x_desc(format!("x ({})", self.unit))
            .y_desc(format!("y ({})", self.unit))
            .axis_desc_style((FONT, 20))
            .label_style((FONT, 16))
            .x_label_formatter(&|v| format!("{v:.2}"))
            .y_label_formatter(&|v| format!("{v:.2}"))
            .draw()
            .map_err(pe)?;
        let real_style = ShapeStyle::from(&BLACK).stroke_width(3);
        let (pts, color, name) = model;
        let model_style = ShapeStyle::from(&color).stroke_width(1);
        for (k, l) in self.lines(self.real).into_iter().enumerate() {
            let s = chart.draw_series(LineSeries::new(l, real_style)).map_err(pe)?;
            if k == 0 {
                s.label("real arm (measured)").legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 24, y)], real_style));
            }
        }
        for (k, l) in self.lines(pts).into_iter().enumerate() {
            let s = chart.draw_series(LineSeries::new(l, model_style)).map_err(pe)?;
            if k == 0 {
                s.label(name).legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 24, y)], color.stroke_width(3)));
            }
        }
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperRight)
            .label_font((FONT, 18))
            .background_style(WHITE.mix(0.9))
            .border_style(BLACK)
            .draw()
            .map_err(pe)?;
        Ok(())
    }
}

impl Figure for Workspace<'_> {
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), String> {
        let root = root.titled(&format!("Images of a {n} × {n} joint grid in the workspace", n = self.per_axis), (FONT, 28)).map_err(pe)?;
        // Equal aspect: one square data box shared by both panels, with room for the legend.
        let all = self.nominal.iter().chain(self.real).chain(self.calibrated);
        let xs: Vec<f64> = all.clone().map(|p| p[0]).collect();
        let ys: Vec<f64> = all.map(|p| p[1]).collect();
        let (x0, x1) = finite_range(&xs).unwrap_or((-1.0, 1.0));
        let (y0, y1) = finite_range(&ys).unwrap_or((-1.0, 1.0));
        let (px, py) = (0.04 * (x1 - x0), 0.04 * (y1 - y0));
        let ranges = ((x0 - px, x1 + px), (y0 - py, y1 + py));
        let areas = root.split_evenly((1, 2));
        self.panel(&areas[0], "Nominal model vs real arm", ranges, (self.nominal, RGBColor(30, 100, 220), "nominal model"))?;
        self.panel(&areas[1], "Calibrated model vs real arm", ranges, (self.calibrated, RGBColor(220, 30, 30), "calibrated model"))
    }
}

/// The images of a `per_axis × per_axis` joint grid (first joint varying slowest, as from
/// [`joint_grid`]) under the nominal, real and calibrated kinematics of a planar arm, drawn as
/// grid lines (paper Figs. 8, 9): left nominal vs real, right calibrated vs real, equal axes.
/// `periodic`: the grid covers a full turn of each joint, so its lines close. Writes
/// `workspace_grid.png` ([`WORKSPACE_SIZE`]) and `.svg`.
pub fn workspace_grid(
    dir: &Path,
    nominal: &[[f64; 2]],
    real: &[[f64; 2]],
    calibrated: &[[f64; 2]],
    per_axis: usize,
    periodic: bool,
    unit: &str,
) -> Result<Vec<PathBuf>, String> {
    let n = per_axis * per_axis;
    if per_axis < 2 || nominal.len() != n || real.len() != n || calibrated.len() != n {
        return Err(format!(
            "workspace grid: expected {n} points per model ({per_axis} per axis, at least 2), got {}, {} and {}",
            nominal.len(),
            real.len(),
            calibrated.len()
        ));
    }
    render(dir, "workspace_grid", WORKSPACE_SIZE, &Workspace { nominal, real, calibrated, per_axis, periodic, unit })
}

// ---------------------------------------------------------------------------------------------
// Histograms (paper Fig. 12)
// ---------------------------------------------------------------------------------------------

struct Histograms<'a> {
    before: Vec<f64>,
    after: Vec<f64>,
    unit: &'a str,
    /// Title override (for the comparison of more than two sets).
    title: String,
}

const BEFORE_COLOR: RGBColor = RGBColor(220, 60, 40);
const AFTER_COLOR: RGBColor = RGBColor(30, 100, 220);

impl Figure for Histograms<'_> {
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), String> {
        let (lo, hi) = finite_range(self.before.iter().chain(&self.after)).ok_or("histogram: no finite errors")?;
        let (lo, hi) = ((lo - 0.05 * (hi - lo)).floor(), (hi + 0.05 * (hi - lo)).ceil());
        let bins = 60usize;
        let width = (hi - lo) / bins as f64;
        let count = |v: &[f64]| {
            let mut c = vec![0usize; bins];
            for &x in v.iter().filter(|x| x.is_finite()) {
                c[(((x - lo) / width) as usize).min(bins - 1)] += 1;
            }
            c
        };
        let (cb, ca) = (count(&self.before), count(&self.after));
        let top = cb.iter().chain(&ca).copied().max().unwrap_or(1).max(1) as f64 * 1.3;
        let mut chart = ChartBuilder::on(root)
            .caption(&self.title, (FONT, 26))
            .margin(18)
            .x_label_area_size(60)
            .y_label_area_size(80)
            .build_cartesian_2d(lo..hi, 0.0..top)
            .map_err(pe)?;
        chart
            .configure_mesh()
            .disable_x_mesh()
            .light_line_style(RGBColor(240, 240, 240))
            .x_desc(format!("position error ({}), log scale", self.unit))
            .y_desc("configurations per bin")
            .axis_desc_style((FONT, 20))
            .label_style((FONT, 16))
            .x_label_formatter(&pow10_label)
            .y_label_formatter(&|v| format!("{v:.0}"))
            .draw()
            .map_err(pe)?;
        for (counts, values, color, name) in
            [(&cb, &self.before, BEFORE_COLOR, "before calibration (nominal)"), (&ca, &self.after, AFTER_COLOR, "after calibration")]
        {
            let med = median(values);
            let label = format!("{name}: median {} {}", fmt_sci(10f64.powf(med)), self.unit);
            chart
                .draw_series(counts.iter().enumerate().filter(|(_, &c)| c > 0).map(|(i, &c)| {
                    let x0 = lo + i as f64 * width;
                    Rectangle::new([(x0, 0.0), (x0 + width, c as f64)], color.mix(0.55).filled())
                }))
                .map_err(pe)?
                .label(label)
                .legend(move |(x, y)| Rectangle::new([(x, y - 7), (x + 20, y + 7)], color.mix(0.55).filled()));
            if med.is_finite() {
                chart.draw_series(std::iter::once(PathElement::new(vec![(med, 0.0), (med, top)], color.stroke_width(2)))).map_err(pe)?;
            }
        }
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperRight)
            .label_font((FONT, 18))
            .background_style(WHITE.mix(0.9))
            .border_style(BLACK)
            .draw()
            .map_err(pe)?;
        Ok(())
    }
}

/// Histograms of the position error before and after calibration on a log10 axis, overlaid, with
/// medians marked (paper Fig. 12). Errors in `unit`. Writes `error_histogram.png`
/// ([`HISTOGRAM_SIZE`]) and `.svg`.
pub fn error_histograms(dir: &Path, before: &[f64], after: &[f64], unit: &str) -> Result<Vec<PathBuf>, String> {
    let fig = Histograms {
        before: before.iter().map(|&e| log_err(e)).collect(),
        after: after.iter().map(|&e| log_err(e)).collect(),
        unit,
        title: format!("Position error before and after calibration ({} and {} configurations)", before.len(), after.len()),
    };
    render(dir, "error_histogram", HISTOGRAM_SIZE, &fig)
}

// ---------------------------------------------------------------------------------------------
// Method comparison (cbd compare)
// ---------------------------------------------------------------------------------------------

struct Comparison<'a> {
    /// name, sorted log10 errors.
    methods: Vec<(String, Vec<f64>)>,
    unit: &'a str,
}

const METHOD_COLORS: [RGBColor; 8] = [
    RGBColor(120, 120, 120),
    RGBColor(230, 120, 20),
    RGBColor(30, 100, 220),
    RGBColor(130, 60, 180),
    RGBColor(20, 150, 80),
    RGBColor(200, 40, 90),
    RGBColor(0, 150, 170),
    RGBColor(150, 110, 40),
];

impl Figure for Comparison<'_> {
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), String> {
        let n = self.methods.len();
        let (lo, hi) = finite_range(self.methods.iter().flat_map(|(_, v)| v)).ok_or("comparison: no finite errors")?;
        // One more decade on the right for the median labels.
        let (lo, hi) = ((lo - 0.03 * (hi - lo)).floor(), (hi + 0.03 * (hi - lo)).ceil() + 1.0);
        let names: Vec<String> = self.methods.iter().map(|(s, _)| s.clone()).collect();
        let name_at = move |v: &f64| -> String {
            let i = v.round();
            if (v - i).abs() < 1e-6 && i >= 0.0 && (i as usize) < names.len() {
                names[names.len() - 1 - i as usize].clone()
            } else {
                String::new()
            }
        };
        let mut chart = ChartBuilder::on(root)
            .caption(
                format!("Position error by method ({} test configurations each)", self.methods.first().map_or(0, |m| m.1.len())),
                (FONT, 26),
            )
            .margin(18)
            .x_label_area_size(60)
            .y_label_area_size(110)
            .build_cartesian_2d(lo..hi, -0.6..(n as f64 - 0.4))
            .map_err(pe)?;
        chart
            .configure_mesh()
            .disable_y_mesh()
            .light_line_style(RGBColor(240, 240, 240))
            .x_desc(format!("position error ({}), log scale — box: quartiles, whiskers: 1st–99th percentile, ×: max", self.unit))
            .axis_desc_style((FONT, 18))
            .label_style((FONT, 18))
            .x_label_formatter(&pow10_label)
            .y_labels(n)
            .y_label_formatter(&name_at)
            .draw()
            .map_err(pe)?;
        for (k, (_, v)) in self.methods.iter().enumerate() {
            if v.is_empty() {
                continue;
            }
            let y = (n - 1 - k) as f64;
            let color = METHOD_COLORS[k % METHOD_COLORS.len()];
            let q = |p| quantile(v, p);
            let (p1, q1, med, q3, p99, max) = (q(0.01), q(0.25), q(0.5), q(0.75), q(0.99), v[v.len() - 1]);
            let h = 0.3;
            let stroke = color.stroke_width(2);
            chart.draw_series(std::iter::once(Rectangle::new([(q1, y - h), (q3, y + h)], color.mix(0.35).filled()))).map_err(pe)?;
            chart.draw_series(std::iter::once(Rectangle::new([(q1, y - h), (q3, y + h)], stroke))).map_err(pe)?;
            chart
                .draw_series([
                    PathElement::new(vec![(med, y - h), (med, y + h)], color.stroke_width(4)),
                    PathElement::new(vec![(p1, y), (q1, y)], stroke),
                    PathElement::new(vec![(q3, y), (p99, y)], stroke),
                    PathElement::new(vec![(p1, y - h / 2.0), (p1, y + h / 2.0)], stroke),
                    PathElement::new(vec![(p99, y - h / 2.0), (p99, y + h / 2.0)], stroke),
                ])
                .map_err(pe)?;
            chart.draw_series(std::iter::once(Cross::new((max, y), 7, color.stroke_width(2)))).map_err(pe)?;
            chart
                .draw_series(std::iter::once(Text::new(
                    format!("median {}", fmt_sci(10f64.powf(med))),
                    (max + 0.015 * (hi - lo), y),
                    TextStyle::from((FONT, 16).into_font()).color(&BLACK).pos(Pos::new(HPos::Left, VPos::Center)),
                )))
                .map_err(pe)?;
        }
        Ok(())
    }
}

/// One chart of every method's error distribution for `cbd compare`: a horizontal box plot per
/// method on a log10 axis (box: quartiles, thick line: median, whiskers: 1st–99th percentile,
/// cross: maximum), in the order given, top to bottom. `methods`: (name, per-configuration
/// position errors in `unit`). Writes `method_comparison.png` ([`COMPARISON_WIDTH`] ×
/// (150 + 70 per method)) and `.svg`.
pub fn method_comparison(dir: &Path, methods: &[(String, Vec<f64>)], unit: &str) -> Result<Vec<PathBuf>, String> {
    if methods.is_empty() {
        return Err("method comparison: no methods".into());
    }
    let methods: Vec<(String, Vec<f64>)> = methods
        .iter()
        .map(|(name, e)| {
            let mut v: Vec<f64> = e.iter().map(|&x| log_err(x)).filter(|x| x.is_finite()).collect();
            v.sort_by(|a, b| a.total_cmp(b));
            (name.clone(), v)
        })
        .collect();
    let size = (COMPARISON_WIDTH, 150 + 70 * methods.len() as u32);
    render(dir, "method_comparison", size, &Comparison { methods, unit })
}

// ---------------------------------------------------------------------------------------------
// Residual against each joint (cbd diagnose)
// ---------------------------------------------------------------------------------------------

/// A found effect's predicted residual as a function of one joint: (label, joint index, curve).
pub type EffectCurve = (String, usize, Vec<(f64, f64)>);

struct Residuals<'a> {
    joint_names: &'a [String],
    joints: &'a [f64],
    residuals: &'a [f64],
    residual_label: &'a str,
    effects: &'a [EffectCurve],
}

impl Figure for Residuals<'_> {
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), String> {
        let nj = self.joint_names.len();
        let root = root.titled("Residual against each joint, with the effects found", (FONT, 28)).map_err(pe)?;
        let rows = nj.div_ceil(2);
        let cols = if nj == 1 { 1 } else { 2 };
        let areas = root.split_evenly((rows, cols));
        let curve_values = self.effects.iter().flat_map(|(_, _, c)| c.iter().map(|p| &p.1));
        let (r0, r1) = finite_range(self.residuals.iter().chain(curve_values)).ok_or("residual plot: no finite residuals")?;
        let pad = 0.06 * (r1 - r0);
        for (j, area) in areas.iter().enumerate().take(nj) {
            let xs: Vec<f64> = self.joints.iter().skip(j).step_by(nj).copied().collect();
            let (x0, x1) = finite_range(&xs).unwrap_or((0.0, 1.0));
            let mut chart = ChartBuilder::on(area)
                .caption(format!("residual vs {}", bare_name(&self.joint_names[j])), (FONT, 22))
                .margin(12)
                .x_label_area_size(50)
                .y_label_area_size(95)
                .build_cartesian_2d(x0..x1, (r0 - pad)..(r1 + pad))
                .map_err(pe)?;
            chart
                .configure_mesh()
                .light_line_style(RGBColor(240, 240, 240))
                .x_desc(self.joint_names[j].as_str())
                .y_desc(self.residual_label)
                .axis_desc_style((FONT, 18))
                .label_style((FONT, 15))
                .y_label_formatter(&|v| linear_label(*v, r1 - r0))
                .draw()
                .map_err(pe)?;
            chart
                .draw_series(
                    xs.iter()
                        .zip(self.residuals)
                        .filter(|(x, r)| x.is_finite() && r.is_finite())
                        .map(|(&x, &r)| Circle::new((x, r), 2, RGBColor(90, 90, 90).mix(0.6).filled())),
                )
                .map_err(pe)?;
            let mut any = false;
            for (k, (label, joint, curve)) in self.effects.iter().enumerate() {
                if *joint != j {
                    continue;
                }
                any = true;
                let color = METHOD_COLORS[1 + k % (METHOD_COLORS.len() - 1)];
                chart
                    .draw_series(LineSeries::new(curve.iter().copied(), color.stroke_width(3)))
                    .map_err(pe)?
                    .label(label.as_str())
                    .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 24, y)], color.stroke_width(3)));
            }
            if any {
                chart
                    .configure_series_labels()
                    .position(SeriesLabelPosition::UpperRight)
                    .label_font((FONT, 16))
                    .background_style(WHITE.mix(0.9))
                    .border_style(BLACK)
                    .draw()
                    .map_err(pe)?;
            }
        }
        Ok(())
    }
}

/// For `cbd diagnose`: the residual (one scalar per configuration — a norm or one component,
/// described by `residual_label` with its unit, e.g. "residual norm (mm)") against each joint
/// angle, one panel per joint (two per row), with each found effect's curve drawn over the panel
/// of its joint. `joints` is row-major, `joint_names.len()` values per configuration; names
/// include the unit. Writes `residual_vs_joint.png` ([`RESIDUAL_WIDTH`] × 420 per row of two
/// joints, plus 40) and `.svg`.
pub fn residual_vs_joint(
    dir: &Path,
    joint_names: &[String],
    joints: &[f64],
    residuals: &[f64],
    residual_label: &str,
    effects: &[EffectCurve],
) -> Result<Vec<PathBuf>, String> {
    let nj = joint_names.len();
    if nj == 0 || joints.len() != nj * residuals.len() || residuals.is_empty() {
        return Err(format!("residual plot: {} joint values for {} residuals and {nj} joints", joints.len(), residuals.len()));
    }
    if let Some((name, j, _)) = effects.iter().find(|(_, j, _)| *j >= nj) {
        return Err(format!("residual plot: effect `{name}` refers to joint {j} of {nj}"));
    }
    let size = (RESIDUAL_WIDTH, 40 + 420 * nj.div_ceil(2) as u32);
    render(dir, "residual_vs_joint", size, &Residuals { joint_names, joints, residuals, residual_label, effects })
}

// ---------------------------------------------------------------------------------------------
// Convergence (cbd report, fits)
// ---------------------------------------------------------------------------------------------

struct Convergence<'a> {
    /// (iteration, energy, train_rms)
    log: &'a [(f64, f64, f64)],
    unit: &'a str,
}

impl Figure for Convergence<'_> {
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), String> {
        let root = root.titled("Levenberg–Marquardt convergence", (FONT, 26)).map_err(pe)?;
        let areas = root.split_evenly((1, 2));
        let last = self.log.iter().map(|r| r.0).fold(1.0, f64::max);
        for (area, pick, title, ylabel) in [
            (&areas[0], 1usize, "energy (16)", "energy, log scale".to_string()),
            (&areas[1], 2usize, "training error (RMS)", format!("RMS training error ({}), log scale", self.unit)),
        ] {
            let pts: Vec<(f64, f64)> = self
                .log
                .iter()
                .map(|r| (r.0, if pick == 1 { r.1 } else { r.2 }))
                .filter(|p| p.1.is_finite() && p.1 > 0.0)
                .map(|(i, v)| (i, v.log10()))
                .collect();
            let (y0, y1) = finite_range(pts.iter().map(|p| &p.1)).unwrap_or((0.0, 1.0));
            let mut chart = ChartBuilder::on(area)
                .caption(title, (FONT, 22))
                .margin(14)
                .x_label_area_size(50)
                .y_label_area_size(80)
                .build_cartesian_2d(0.0..last, (y0 - 0.2).floor()..(y1 + 0.2).ceil())
                .map_err(pe)?;
            chart
                .configure_mesh()
                .light_line_style(RGBColor(240, 240, 240))
                .x_desc("iteration")
                .y_desc(ylabel)
                .axis_desc_style((FONT, 18))
                .label_style((FONT, 15))
                .x_label_formatter(&|v| format!("{v:.0}"))
                .y_label_formatter(&pow10_label)
                .draw()
                .map_err(pe)?;
            let color = if pick == 1 { BEFORE_COLOR } else { AFTER_COLOR };
            chart.draw_series(LineSeries::new(pts.iter().copied(), color.stroke_width(2))).map_err(pe)?;
            chart.draw_series(pts.iter().map(|&p| Circle::new(p, 3, color.filled()))).map_err(pe)?;
        }
        Ok(())
    }
}

/// The solver's per-iteration log: energy and RMS training error (in `unit`) against iteration,
/// both on log axes. `log`: (iteration, energy, train_rms). Writes `convergence.png`
/// ([`CONVERGENCE_SIZE`]) and `.svg`.
pub fn convergence(dir: &Path, log: &[(usize, f64, f64)], unit: &str) -> Result<Vec<PathBuf>, String> {
    let log: Vec<(f64, f64, f64)> = log.iter().map(|&(i, e, r)| (i as f64, e, r)).collect();
    render(dir, "convergence", CONVERGENCE_SIZE, &Convergence { log: &log, unit })
}

/// [`convergence`] as an SVG document in a string, for inline use in a page.
pub fn convergence_svg(log: &[(usize, f64, f64)], unit: &str) -> Result<String, String> {
    let log: Vec<(f64, f64, f64)> = log.iter().map(|&(i, e, r)| (i as f64, e, r)).collect();
    render_svg_string(CONVERGENCE_SIZE, &Convergence { log: &log, unit })
}

// ---------------------------------------------------------------------------------------------
// All demo figures at once
// ---------------------------------------------------------------------------------------------

/// Batch kinematics of a planar arm: joints row-major (2 per row) → positions row-major (2 per row).
pub type PlanarMap<'a> = &'a dyn Fn(&[f64]) -> Result<Vec<f64>, String>;

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
pub fn demo_figures(dir: &Path, inputs: &DemoPlotInputs) -> Result<Vec<PathBuf>, String> {
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

pub use crate::report::stats::position_errors;

#[cfg(test)]
mod tests {
    use super::*;

    fn tmp(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("cbd-plots-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        dir
    }

    /// Width and height from a PNG's IHDR chunk, after checking the signature.
    fn png_size(path: &Path) -> (u32, u32) {
        let bytes = std::fs::read(path).unwrap();
        assert!(bytes.len() > 33, "{}: too short", path.display());
        assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n", "{}: PNG signature", path.display());
        assert_eq!(&bytes[12..16], b"IHDR");
        let be = |i: usize| u32::from_be_bytes([bytes[i], bytes[i + 1], bytes[i + 2], bytes[i + 3]]);
        assert_eq!(&bytes[bytes.len() - 8..bytes.len() - 4], b"IEND", "{}: IEND chunk", path.display());
        (be(16), be(20))
    }

    fn check_svg(path: &Path, must_contain: &[&str]) {
        let text = std::fs::read_to_string(path).unwrap();
        let t = text.trim();
        assert!(t.starts_with("<svg") || t.starts_with("<?xml"), "{}: starts with {:?}", path.display(), &t[..t.len().min(40)]);
        assert!(t.ends_with("</svg>"), "{}: does not close </svg>", path.display());
        assert_eq!(t.matches("<svg").count(), 1);
        for s in must_contain {
            assert!(text.contains(s), "{}: lacks {s:?}", path.display());
        }
    }

    fn check_pair(files: &[PathBuf], stem: &str, size: (u32, u32), svg_text: &[&str]) {
        assert_eq!(files.len(), 2, "{files:?}");
        assert!(files[0].ends_with(format!("{stem}.png")) && files[1].ends_with(format!("{stem}.svg")), "{files:?}");
        assert_eq!(png_size(&files[0]), size);
        check_svg(&files[1], svg_text);
    }

    /// Synthetic RR-like errors: about 0.1 before, about 1e-6 after, varying over the grid.
    fn rr_like(grid: &[(f64, f64)]) -> (Vec<f64>, Vec<f64>) {
        let before = grid.iter().map(|&(a, b)| 0.1 + 0.05 * (a + 0.5 * b).sin()).collect();
        let after = grid.iter().map(|&(a, b)| 1e-6 * (1.5 + (3.0 * a).cos() * b.sin())).collect();
        (before, after)
    }

    #[test]
    fn heatmaps_of_a_grid_are_written_as_png_and_svg() {
        let dir = tmp("heat");
        let grid = joint_grid(12, 0.0, 2.0 * std::f64::consts::PI);
        assert_eq!(grid.len(), 144);
        let (before, after) = rr_like(&grid);
        let files = error_heatmaps(&dir, "q1 (rad)", "q2 (rad)", &grid, &before, &after, 12, "length units").unwrap();
        check_pair(
            &files,
            "error_heatmaps",
            HEATMAP_SIZE,
            &["q1 (rad)", "Before calibration", "After calibration", "log10 position error (length units)"],
        );
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn heatmap_bins_put_one_grid_point_per_cell_and_share_one_scale() {
        let grid = joint_grid(5, 0.0, 5.0);
        let errors: Vec<f64> = (0..25).map(|k| 10f64.powi(-(k as i32 % 5))).collect();
        let range = finite_range(grid.iter().map(|p| &p.0)).unwrap();
        assert_eq!(range, (0.0, 4.0));
        let bins = bin_log_errors(&grid, &errors, 5, range, range);
        for (k, b) in bins.iter().enumerate() {
            assert!((b - (-((k % 5) as f64))).abs() < 1e-12, "bin {k}: {b}");
        }
        // Scattered points: averaged in log space; empty cells NaN.
        let bins = bin_log_errors(&[(0.0, 0.0), (0.1, 0.0), (4.0, 4.0)], &[1e-2, 1e-4, 1.0], 5, range, range);
        assert!((bins[0] + 3.0).abs() < 1e-12 && bins[24].abs() < 1e-12 && bins[1].is_nan());
        // Exact zeros do not poison the scale.
        assert_eq!(log_err(0.0), ERROR_FLOOR.log10());
    }

    #[test]
    fn heatmaps_reject_mismatched_inputs() {
        let dir = tmp("heat-bad");
        let grid = joint_grid(3, 0.0, 1.0);
        assert!(error_heatmaps(&dir, "a", "b", &grid, &[0.1; 9], &[0.1; 8], 3, "m").is_err());
        assert!(error_heatmaps(&dir, "a", "b", &[], &[], &[], 3, "m").is_err());
        assert!(workspace_grid(&dir, &[[0.0; 2]; 4], &[[0.0; 2]; 4], &[[0.0; 2]; 3], 2, false, "m").is_err());
        assert!(residual_vs_joint(&dir, &["q1".into()], &[0.0, 1.0], &[0.5], "r", &[]).is_err());
        assert!(method_comparison(&dir, &[], "m").is_err());
    }

    #[test]
    fn workspace_histogram_comparison_residual_and_convergence_figures() {
        let dir = tmp("all");
        let n = 8;
        let grid = joint_grid(n, 0.0, 2.0 * std::f64::consts::PI);
        let fk = |l1: f64, l2: f64, dx: f64| -> Vec<[f64; 2]> {
            grid.iter().map(|&(a, b)| [dx + l1 * a.cos() + l2 * (a + b).cos(), l1 * a.sin() + l2 * (a + b).sin()]).collect()
        };
        let (nominal, real) = (fk(1.0, 0.5, 0.0), fk(1.1, 0.45, 0.02));
        let calibrated: Vec<[f64; 2]> = real.iter().map(|p| [p[0] + 1e-6, p[1]]).collect();
        let files = workspace_grid(&dir, &nominal, &real, &calibrated, n, true, "length units").unwrap();
        check_pair(&files, "workspace_grid", WORKSPACE_SIZE, &["nominal model", "calibrated model", "x (length units)"]);

        let before: Vec<f64> = nominal.iter().zip(&real).map(|(p, q)| ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2)).sqrt()).collect();
        let after: Vec<f64> = (0..before.len()).map(|i| 1e-6 * (1.0 + (i % 5) as f64)).collect();
        let files = error_histograms(&dir, &before, &after, "length units").unwrap();
        check_pair(&files, "error_histogram", HISTOGRAM_SIZE, &["before calibration", "after calibration", "log scale"]);

        let methods = vec![
            ("nominal".to_string(), before.clone()),
            ("krr".to_string(), after.iter().map(|e| e * 100.0).collect()),
            ("cbd".to_string(), after.clone()),
        ];
        let files = method_comparison(&dir, &methods, "mm").unwrap();
        check_pair(&files, "method_comparison", (COMPARISON_WIDTH, 150 + 70 * 3), &["nominal", "krr", "cbd", "median"]);

        let names = vec!["q1 (rad)".to_string(), "q2 (rad)".to_string(), "q3 (rad)".to_string()];
        let joints: Vec<f64> = (0..60).map(|i| (i as f64 * 0.7).sin() * 3.0).collect();
        let residuals: Vec<f64> = joints.chunks(3).map(|q| 0.2 * q[1].sin()).collect();
        let curve: Vec<(f64, f64)> = (0..50).map(|i| (-3.0 + 0.12 * i as f64, 0.2 * (-3.0 + 0.12 * i as f64).sin())).collect();
        let files =
            residual_vs_joint(&dir, &names, &joints, &residuals, "residual norm (mm)", &[("elbow gravity".into(), 1, curve)]).unwrap();
        check_pair(&files, "residual_vs_joint", (RESIDUAL_WIDTH, 40 + 420 * 2), &["elbow gravity", "residual norm (mm)"]);

        let log: Vec<(usize, f64, f64)> = (0..6).map(|i| (i, 10f64.powi(-(i as i32)), 0.1 * 10f64.powi(-(i as i32)))).collect();
        let files = convergence(&dir, &log, "length units").unwrap();
        check_pair(&files, "convergence", CONVERGENCE_SIZE, &["iteration", "RMS training error"]);
        let svg = convergence_svg(&log, "length units").unwrap();
        assert!(svg.contains("<svg") && svg.trim_end().ends_with("</svg>"));
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn demo_figures_from_planar_maps() {
        let dir = tmp("demo");
        let fk = |l1: f64, l2: f64| {
            move |q: &[f64]| -> Result<Vec<f64>, String> {
                Ok(q.chunks_exact(2)
                    .flat_map(|x| [l1 * x[0].cos() + l2 * (x[0] + x[1]).cos(), l1 * x[0].sin() + l2 * (x[0] + x[1]).sin()])
                    .collect())
            }
        };
        let (nominal, real) = (fk(1.0, 0.5), fk(1.1, 0.45));
        let calibrated = |q: &[f64]| -> Result<Vec<f64>, String> { Ok(fk(1.1, 0.45)(q)?.into_iter().map(|v| v + 1e-6).collect()) };
        let before = vec![0.1, 0.12, 0.08];
        let after = vec![1e-6, 2e-6, 3e-6];
        let inputs = DemoPlotInputs {
            nominal: &nominal,
            real: &real,
            calibrated: &calibrated,
            joint_labels: ["q1 (rad)", "q2 (rad)"],
            test_before: &before,
            test_after: &after,
            fit_log: &[(0, 1.0, 0.1), (1, 1e-3, 1e-4)],
            unit: "length units",
            heatmap_per_axis: 16,
            workspace_per_axis: 6,
        };
        let files = demo_figures(&dir, &inputs).unwrap();
        let names: Vec<String> = files.iter().map(|p| p.file_name().unwrap().to_string_lossy().into_owned()).collect();
        for stem in ["error_heatmaps", "workspace_grid", "error_histogram", "convergence"] {
            assert!(names.contains(&format!("{stem}.png")) && names.contains(&format!("{stem}.svg")), "{names:?}");
        }
        assert!(files.iter().all(|p| p.exists()));
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn helpers() {
        assert_eq!(viridis(0.0), RGBColor(68, 1, 84));
        assert_eq!(viridis(1.0), RGBColor(253, 231, 37));
        assert_eq!(viridis(f64::NAN), viridis(0.0));
        assert_eq!(bare_name("q1 (rad)"), "q1");
        assert_eq!(linear_label(-5.55e-17, 0.6), "0");
        assert_eq!(linear_label(0.25, 0.6), "0.250");
        assert_eq!(pow10_label(&-3.0), "1e-3");
        assert_eq!(median(&[3.0, f64::NAN, 1.0, 2.0]), 2.0);
    }

    /// The real RR demo pipeline (simulate, fit, load the blob, evaluate) drawn to
    /// `$CBD_PLOTS_DIR` (default: the temp dir's `cbd-rr-plots`), for looking at the figures:
    /// `cargo test -p cbd-trainer --lib report::plots::tests::rr_demo_figures -- --ignored`.
    #[test]
    #[ignore = "fits the RR demo (seconds to minutes); run by hand to look at the figures"]
    fn rr_demo_figures() {
        use crate::simulate::{configurations, rr, Sampling};
        let dir = std::env::var_os("CBD_PLOTS_DIR").map(PathBuf::from).unwrap_or_else(|| std::env::temp_dir().join("cbd-rr-plots"));
        let nominal_model = rr::nominal();
        let real_arm = rr::RealRr::default();
        let train = real_arm.measure(&configurations(Sampling::Grid { per_axis: 16 }, 2));
        let test = real_arm.measure(&configurations(Sampling::Uniform { count: 3000, seed: 2026 }, 2));
        let fit = crate::solver::fit_cbd(&nominal_model, &train, &crate::solver::CbdOptions::paper_rr()).unwrap();
        let nominal = |q: &[f64]| -> Result<Vec<f64>, String> {
            Ok(q.chunks_exact(2).flat_map(|x| cbd_runtime::nominal::forward_kinematics(&nominal_model, x).position[..2].to_vec()).collect())
        };
        let real = |q: &[f64]| -> Result<Vec<f64>, String> { Ok(q.chunks_exact(2).flat_map(|x| real_arm.position(x)).collect()) };
        let calibrated = |q: &[f64]| crate::predict::evaluate_blob(&fit.blob, q);
        let test_before = position_errors(&nominal(&test.joints).unwrap(), &test.positions, 2);
        let test_after = position_errors(&calibrated(&test.joints).unwrap(), &test.positions, 2);
        let log: Vec<(usize, f64, f64)> = fit.report.log.iter().map(|r| (r.iteration, r.energy, r.train_rms)).collect();
        let inputs = DemoPlotInputs {
            nominal: &nominal,
            real: &real,
            calibrated: &calibrated,
            joint_labels: ["q1 (rad)", "q2 (rad)"],
            test_before: &test_before,
            test_after: &test_after,
            fit_log: &log,
            unit: "length units",
            heatmap_per_axis: 64,
            workspace_per_axis: 16,
        };
        let files = demo_figures(&dir, &inputs).unwrap();
        eprintln!("{} LM iterations; wrote {files:?}", fit.report.iterations);
    }
}

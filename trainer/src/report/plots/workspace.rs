//! The workspace grid: nominal, real and calibrated images of a joint grid (paper Figs. 8, 9).

use super::chart::*;
use plotters::coord::Shift;
use plotters::prelude::*;
use std::path::{Path, PathBuf};

/// Pixel size of [`workspace_grid`].
pub const WORKSPACE_SIZE: (u32, u32) = (1400, 720);

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
    ) -> crate::Result<()> {
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
        draw_legend(&mut chart, 18)?;
        Ok(())
    }
}

impl Figure for Workspace<'_> {
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> crate::Result<()> {
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
) -> crate::Result<Vec<PathBuf>> {
    let n = per_axis * per_axis;
    if per_axis < 2 || nominal.len() != n || real.len() != n || calibrated.len() != n {
        return Err(crate::Error::Plot(format!(
            "workspace grid: expected {n} points per model ({per_axis} per axis, at least 2), got {}, {} and {}",
            nominal.len(),
            real.len(),
            calibrated.len()
        )));
    }
    render(dir, "workspace_grid", WORKSPACE_SIZE, &Workspace { nominal, real, calibrated, per_axis, periodic, unit })
}

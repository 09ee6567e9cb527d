//! The trend of a calibration's checks (`cbd report --checks`): mean error with the noise floor as
//! a band, and p with α as a line, against time; one point per `cbd check --log` line.

use super::chart::*;
use crate::report::checks::{utc_text, CheckEntry};
use plotters::coord::Shift;
use plotters::prelude::*;
use std::path::{Path, PathBuf};

/// Pixel size of [`check_history`].
pub const HISTORY_SIZE: (u32, u32) = (1100, 820);

const BAND_COLOR: RGBColor = RGBColor(120, 190, 120);
const ALPHA_COLOR: RGBColor = RGBColor(120, 120, 120);

struct History<'a> {
    entries: &'a [CheckEntry],
    unit: &'a str,
}

/// The time axis: the checks' span, padded by 5 % (a minute each side when they share a second).
fn time_range(entries: &[CheckEntry]) -> (f64, f64) {
    let lo = entries.iter().map(|e| e.seconds).min().unwrap_or(0) as f64;
    let hi = entries.iter().map(|e| e.seconds).max().unwrap_or(0) as f64;
    let pad = if hi - lo < 1.0 { 60.0 } else { 0.05 * (hi - lo) };
    (lo - pad, hi + pad)
}

/// A tick of the time axis: the date, or the time of day when the axis spans less than two days.
fn time_label(v: f64, span: f64) -> String {
    let t = utc_text(v.round() as i64);
    if span < 600.0 {
        t[11..19].to_string()
    } else if span < 2.0 * 86_400.0 {
        t[5..16].replace('T', " ")
    } else {
        t[..10].to_string()
    }
}

/// A per-check value as a step across the axis: held from the axis' left end to the first check,
/// between checks, and to the right end after the last.
fn steps(entries: &[(f64, f64)], x0: f64, x1: f64) -> Vec<(f64, f64)> {
    let mut out = Vec::new();
    for (i, &(x, y)) in entries.iter().enumerate() {
        let from = if i == 0 { x0 } else { x };
        out.push((from, y));
        let to = entries.get(i + 1).map_or(x1, |n| n.0);
        out.push((to, y));
    }
    out
}

impl Figure for History<'_> {
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> crate::Result<()> {
        let root = root.titled("Checks of the calibration over time", (FONT, 26)).map_err(pe)?;
        let areas = root.split_evenly((2, 1));
        let (x0, x1) = time_range(self.entries);
        let span = x1 - x0;
        let xs: Vec<f64> = self.entries.iter().map(|e| e.seconds as f64).collect();
        let color = |e: &CheckEntry| if e.verdict == "changed" { BEFORE_COLOR } else { AFTER_COLOR };

        // Mean error, log axis, with the floor's band.
        let floors: Vec<(f64, (f64, f64))> =
            self.entries.iter().zip(&xs).filter_map(|(e, &x)| e.floor.map(|(f, l)| (x, (log_err(f), log_err(l))))).collect();
        let errors: Vec<f64> = self.entries.iter().map(|e| log_err(e.mean_error)).collect();
        let all: Vec<f64> = errors.iter().copied().chain(floors.iter().flat_map(|(_, (f, l))| [*f, *l])).collect();
        let (y0, y1) = finite_range(all.iter()).unwrap_or((-3.0, 0.0));
        let mut chart = ChartBuilder::on(&areas[0])
            .caption(format!("mean error ({})", self.unit), (FONT, 22))
            .margin(14)
            .x_label_area_size(50)
            .y_label_area_size(90)
            // Headroom above the data for the legend.
            .build_cartesian_2d(x0..x1, (y0 - 0.15)..(y1 + 0.15 + 0.35 * (y1 - y0 + 0.3)))
            .map_err(pe)?;
        chart
            .configure_mesh()
            .light_line_style(RGBColor(240, 240, 240))
            .x_desc("time (UTC)")
            .y_desc(format!("mean error ({}), log scale", self.unit))
            .axis_desc_style((FONT, 18))
            .label_style((FONT, 15))
            .x_labels(6)
            .x_label_formatter(&|v| time_label(*v, span))
            .y_labels(6)
            .y_label_formatter(&pow10_label)
            .draw()
            .map_err(pe)?;
        if !floors.is_empty() {
            let lower = steps(&floors.iter().map(|(x, (f, _))| (*x, *f)).collect::<Vec<_>>(), x0, x1);
            let upper = steps(&floors.iter().map(|(x, (_, l))| (*x, *l)).collect::<Vec<_>>(), x0, x1);
            let polygon: Vec<(f64, f64)> = lower.iter().copied().chain(upper.iter().rev().copied()).collect();
            chart
                .draw_series(std::iter::once(Polygon::new(polygon, BAND_COLOR.mix(0.3).filled())))
                .map_err(pe)?
                .label("noise floor (band: still at it)")
                .legend(|(x, y)| Rectangle::new([(x, y - 6), (x + 18, y + 6)], BAND_COLOR.mix(0.3).filled()));
            chart.draw_series(LineSeries::new(lower, BAND_COLOR.stroke_width(2))).map_err(pe)?;
        }
        let points: Vec<(f64, f64)> = xs.iter().copied().zip(errors.iter().copied()).collect();
        chart.draw_series(LineSeries::new(points.iter().copied(), RGBColor(150, 150, 150).stroke_width(1))).map_err(pe)?;
        for verdict in ["holds", "changed"] {
            let c = if verdict == "changed" { BEFORE_COLOR } else { AFTER_COLOR };
            let mine: Vec<(f64, f64)> = self.entries.iter().zip(&points).filter(|(e, _)| e.verdict == verdict).map(|(_, p)| *p).collect();
            if mine.is_empty() {
                continue;
            }
            chart
                .draw_series(mine.iter().map(|&p| Circle::new(p, 5, c.filled())))
                .map_err(pe)?
                .label(verdict)
                .legend(move |(x, y)| Circle::new((x + 9, y), 5, c.filled()));
        }
        draw_legend(&mut chart, 15)?;

        // p, log axis, with α.
        let ps: Vec<f64> = self.entries.iter().map(|e| log_err(e.p_value)).collect();
        let alphas: Vec<(f64, f64)> = self.entries.iter().zip(&xs).filter_map(|(e, &x)| e.alpha.map(|a| (x, a.log10()))).collect();
        let lowest = ps.iter().chain(alphas.iter().map(|(_, a)| a)).fold(0.0f64, |m, &v| m.min(v));
        let mut chart = ChartBuilder::on(&areas[1])
            .caption("p of the check (χ²)", (FONT, 22))
            .margin(14)
            .x_label_area_size(50)
            .y_label_area_size(90)
            // Headroom above p = 1 for the legend (no ticks there).
            .build_cartesian_2d(x0..x1, (lowest - 0.3).floor()..(0.25 * (0.3 - lowest).ceil()).max(1.0))
            .map_err(pe)?;
        chart
            .configure_mesh()
            .light_line_style(RGBColor(240, 240, 240))
            .x_desc("time (UTC)")
            .y_desc("p, log scale (below 1e-16 drawn at it)")
            .axis_desc_style((FONT, 18))
            .label_style((FONT, 15))
            .x_labels(6)
            .x_label_formatter(&|v| time_label(*v, span))
            .y_label_formatter(&|v| if *v > 1e-9 { String::new() } else { pow10_label(v) })
            .draw()
            .map_err(pe)?;
        if !alphas.is_empty() {
            chart
                .draw_series(LineSeries::new(steps(&alphas, x0, x1), ALPHA_COLOR.stroke_width(2)))
                .map_err(pe)?
                .label("α (changed below)")
                .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], ALPHA_COLOR.stroke_width(2)));
        }
        let points: Vec<(f64, f64)> = xs.iter().copied().zip(ps.iter().copied()).collect();
        chart.draw_series(LineSeries::new(points.iter().copied(), RGBColor(150, 150, 150).stroke_width(1))).map_err(pe)?;
        chart.draw_series(self.entries.iter().zip(&points).map(|(e, &p)| Circle::new(p, 5, color(e).filled()))).map_err(pe)?;
        if !alphas.is_empty() {
            draw_legend(&mut chart, 15)?;
        }
        Ok(())
    }
}

/// The checks' trend: mean error (in `unit`) with the floor's band, and p with α, against time.
/// Writes `check_history.png` ([`HISTORY_SIZE`]) and `.svg`.
pub fn check_history(dir: &Path, entries: &[CheckEntry], unit: &str) -> crate::Result<Vec<PathBuf>> {
    render(dir, "check_history", HISTORY_SIZE, &History { entries, unit })
}

/// [`check_history`] as an SVG document in a string, for inline use in a page.
pub fn check_history_svg(entries: &[CheckEntry], unit: &str) -> crate::Result<String> {
    render_svg_string(HISTORY_SIZE, &History { entries, unit })
}

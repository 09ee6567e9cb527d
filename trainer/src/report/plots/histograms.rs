//! Histograms of the test errors before and after calibration (paper Fig. 12).

use super::chart::*;
use crate::report::stats::median;
use plotters::coord::Shift;
use plotters::prelude::*;
use std::path::{Path, PathBuf};

/// Pixel size of [`error_histograms`].
pub const HISTOGRAM_SIZE: (u32, u32) = (1100, 640);

struct Histograms<'a> {
    before: Vec<f64>,
    after: Vec<f64>,
    unit: &'a str,
    /// Title override (for the comparison of more than two sets).
    title: String,
}

impl Figure for Histograms<'_> {
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> crate::Result<()> {
        let (lo, hi) =
            finite_range(self.before.iter().chain(&self.after)).ok_or_else(|| crate::Error::Plot("histogram: no finite errors".into()))?;
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
        draw_legend(&mut chart, 18)?;
        Ok(())
    }
}

/// Histograms of the position error before and after calibration on a log10 axis, overlaid, with
/// medians marked (paper Fig. 12). Errors in `unit`. Writes `error_histogram.png`
/// ([`HISTOGRAM_SIZE`]) and `.svg`.
pub fn error_histograms(dir: &Path, before: &[f64], after: &[f64], unit: &str) -> crate::Result<Vec<PathBuf>> {
    let fig = Histograms {
        before: before.iter().map(|&e| log_err(e)).collect(),
        after: after.iter().map(|&e| log_err(e)).collect(),
        unit,
        title: format!("Position error before and after calibration ({} and {} configurations)", before.len(), after.len()),
    };
    render(dir, "error_histogram", HISTOGRAM_SIZE, &fig)
}

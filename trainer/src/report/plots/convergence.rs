//! Energy and training RMS per solver iteration (`cbd report`, fits).

use super::chart::*;
use plotters::coord::Shift;
use plotters::prelude::*;
use std::path::{Path, PathBuf};

/// Pixel size of [`convergence`].
pub const CONVERGENCE_SIZE: (u32, u32) = (1100, 560);

struct Convergence<'a> {
    /// (iteration, energy, train_rms)
    log: &'a [(f64, f64, f64)],
    unit: &'a str,
}

impl Figure for Convergence<'_> {
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> crate::Result<()> {
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
pub fn convergence(dir: &Path, log: &[(usize, f64, f64)], unit: &str) -> crate::Result<Vec<PathBuf>> {
    let log: Vec<(f64, f64, f64)> = log.iter().map(|&(i, e, r)| (i as f64, e, r)).collect();
    render(dir, "convergence", CONVERGENCE_SIZE, &Convergence { log: &log, unit })
}

/// [`convergence`] as an SVG document in a string, for inline use in a page.
pub fn convergence_svg(log: &[(usize, f64, f64)], unit: &str) -> crate::Result<String> {
    let log: Vec<(f64, f64, f64)> = log.iter().map(|&(i, e, r)| (i as f64, e, r)).collect();
    render_svg_string(CONVERGENCE_SIZE, &Convergence { log: &log, unit })
}

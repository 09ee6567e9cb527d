//! Every method's test errors side by side (`cbd compare`).

use super::chart::*;
use crate::report::stats::quantile;
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use std::path::{Path, PathBuf};

/// Width of [`method_comparison`]; its height is 150 + 70 per method.
pub const COMPARISON_WIDTH: u32 = 1100;

struct Comparison<'a> {
    /// name, sorted log10 errors.
    methods: Vec<(String, Vec<f64>)>,
    unit: &'a str,
}

impl Figure for Comparison<'_> {
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> crate::Result<()> {
        let n = self.methods.len();
        let (lo, hi) = finite_range(self.methods.iter().flat_map(|(_, v)| v))
            .ok_or_else(|| crate::Error::Plot("comparison: no finite errors".into()))?;
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
pub fn method_comparison(dir: &Path, methods: &[(String, Vec<f64>)], unit: &str) -> crate::Result<Vec<PathBuf>> {
    if methods.is_empty() {
        return Err(crate::Error::Plot("method comparison: no methods".into()));
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

//! The residual against each joint, with the effects found (`cbd diagnose`).

use super::chart::*;
use plotters::coord::Shift;
use plotters::prelude::*;
use std::path::{Path, PathBuf};

/// Width of [`residual_vs_joint`]; its height is 420 per row of (up to) two joints.
pub const RESIDUAL_WIDTH: u32 = 1400;

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
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> crate::Result<()> {
        let nj = self.joint_names.len();
        // The title promises curves only when there are some to draw.
        let title = if self.effects.is_empty() {
            "Residual against each joint"
        } else {
            "Residual against each joint, and the part of it each effect found explains"
        };
        let root = root.titled(title, (FONT, 28)).map_err(pe)?;
        let rows = nj.div_ceil(2);
        let cols = if nj == 1 { 1 } else { 2 };
        let areas = root.split_evenly((rows, cols));
        let curve_values = self.effects.iter().flat_map(|(_, _, c)| c.iter().map(|p| &p.1));
        let (r0, r1) = finite_range(self.residuals.iter().chain(curve_values))
            .ok_or_else(|| crate::Error::Plot("residual plot: no finite residuals".into()))?;
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
                draw_legend(&mut chart, 16)?;
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
) -> crate::Result<Vec<PathBuf>> {
    let nj = joint_names.len();
    if nj == 0 || joints.len() != nj * residuals.len() || residuals.is_empty() {
        return Err(crate::Error::InvalidInput(format!(
            "residual plot: {} joint values for {} residuals and {nj} joints",
            joints.len(),
            residuals.len()
        )));
    }
    if let Some((name, j, _)) = effects.iter().find(|(_, j, _)| *j >= nj) {
        return Err(crate::Error::InvalidInput(format!("residual plot: effect `{name}` refers to joint {j} of {nj}")));
    }
    let size = (RESIDUAL_WIDTH, 40 + 420 * nj.div_ceil(2) as u32);
    render(dir, "residual_vs_joint", size, &Residuals { joint_names, joints, residuals, residual_label, effects })
}

//! Errors of data with several tool points per pose (docs/DESIGN.md §12): per tool point, and as
//! the tool frame's position and orientation — the least-squares frame of the measured points
//! against that of the predicted points (Kabsch/Horn, `nominal::tool_points::tool_frame`).

use crate::nominal::tool_points::{rotation_angle, tool_frame};
use crate::report::stats::ErrorStats;

/// A pose's errors, over the test poses.
#[derive(Debug, Clone, PartialEq)]
pub struct PoseErrors {
    /// Position error of each tool point (model length unit).
    pub per_point: Vec<ErrorStats>,
    /// Distance between the two least-squares frames' origins (the tool frame's origin; length unit);
    /// `None` with fewer than 3 tool points (no frame).
    pub frame_position: Option<ErrorStats>,
    /// Angle between the two frames' orientations, degrees; `None` with fewer than 3 tool points.
    pub orientation_deg: Option<ErrorStats>,
    /// Root mean square of the orientation errors, degrees (the figure §12's noise bound is for).
    pub orientation_rms_deg: Option<f64>,
}

/// Column widths of a pose table: each line's indent, the name column, the numbers.
pub struct PoseTableLayout {
    pub indent: &'static str,
    pub name_width: usize,
    pub number_width: usize,
}

/// The table of each named model's mean error per tool point, of the tool frame's origin and of its
/// orientation (degrees: mean and RMS) under `heading`; empty when no row has pose errors.
pub fn pose_table<'a>(heading: &str, first_column: &str, layout: &PoseTableLayout, rows: &[(&'a str, Option<&'a PoseErrors>)]) -> String {
    let PoseTableLayout { indent, name_width: nw, number_width: w } = *layout;
    let Some(points) = rows.iter().find_map(|(_, p)| p.map(|p| p.per_point.len())) else { return String::new() };
    let mut out = format!("\n{heading}:\n{indent}{first_column:<nw$}");
    for j in 1..=points {
        out += &format!(" {:>w$}", format!("point {j}"));
    }
    out += &format!(" {:>w$} {:>11} {:>11}\n", "frame", "orient mean", "orient rms");
    for (name, p) in rows {
        let Some(p) = p else { continue };
        out += &format!("{indent}{name:<nw$}");
        for s in &p.per_point {
            out += &format!(" {:>w$.4e}", s.mean);
        }
        let frame = p.frame_position.map_or(f64::NAN, |s| s.mean);
        let (mean, rms) = (p.orientation_deg.map_or(f64::NAN, |s| s.mean), p.orientation_rms_deg.unwrap_or(f64::NAN));
        out += &format!(" {frame:>w$.4e} {mean:>11.4e} {rms:>11.4e}\n");
    }
    out
}

impl PoseErrors {
    /// The errors of `predicted` against `measured` (rows pose-major, `tool_points.len()` per pose,
    /// 3 coordinates each). `None` for one point per pose or a 2-D task space.
    pub fn of(tool_points: &[[f64; 3]], predicted: &[f64], measured: &[f64], task_dim: usize) -> Option<PoseErrors> {
        let p = tool_points.len();
        if p < 2 || task_dim != 3 {
            return None;
        }
        let errors = crate::report::plots::position_errors(predicted, measured, 3);
        let per_point = (0..p).map(|j| ErrorStats::of_errors(&errors.iter().skip(j).step_by(p).copied().collect::<Vec<_>>())).collect();
        let as_points = |v: &[f64]| -> Vec<[f64; 3]> { v.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect() };
        let (mut position, mut angle) = (Vec::new(), Vec::new());
        if p >= 3 {
            for (a, b) in predicted.chunks_exact(3 * p).zip(measured.chunks_exact(3 * p)) {
                let (Some(fa), Some(fb)) = (tool_frame(tool_points, &as_points(a)), tool_frame(tool_points, &as_points(b))) else {
                    position.push(f64::NAN);
                    angle.push(f64::NAN);
                    continue;
                };
                position.push(crate::nominal::norm(crate::nominal::sub(fa.translation(), fb.translation())));
                angle.push(rotation_angle(&fa, &fb).to_degrees());
            }
        }
        let rms = (!angle.is_empty()).then(|| (angle.iter().map(|a| a * a).sum::<f64>() / angle.len() as f64).sqrt());
        Some(PoseErrors {
            per_point,
            frame_position: (p >= 3).then(|| ErrorStats::of_errors(&position)),
            orientation_deg: (p >= 3).then(|| ErrorStats::of_errors(&angle)),
            orientation_rms_deg: rms,
        })
    }

    /// The JSON: `{"points": [{mean, median, p99, max}, …], "frame_position": {…}, "orientation_deg": {…},
    /// "orientation_rms_deg": x}`.
    pub fn to_json(&self) -> serde_json::Value {
        let stats = |s: &ErrorStats| serde_json::json!({"mean": s.mean, "median": s.median, "p99": s.p99, "max": s.max});
        serde_json::json!({
            "points": self.per_point.iter().map(stats).collect::<Vec<_>>(),
            "frame_position": self.frame_position.as_ref().map(stats),
            "orientation_deg": self.orientation_deg.as_ref().map(stats),
            "orientation_rms_deg": self.orientation_rms_deg,
        })
    }
}

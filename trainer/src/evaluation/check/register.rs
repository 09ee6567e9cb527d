//! The fresh rows' rigid frame (a tracker set up anew): the motion carrying the measured points
//! onto the blob's predictions (Kabsch/Horn, `nominal::rigid_fit`), and the frame's tangent at the
//! registered points — the 6 columns δx_i = δt + ω × (x_i − x̄) the statistic projects out
//! (docs/DESIGN.md "cbd check": the generalised-least-squares residual on dim r − 6 degrees of
//! freedom, so the remaining small frame error the test cannot tell from a change is not tested).

use crate::nominal::rigid_fit::{axis_angle, rigid_fit};
use crate::nominal::Frame;
use faer::Mat;

/// The frame's degrees of freedom (3-D: three translations, three rotations).
pub const FRAME_DOF: usize = 6;

/// The fitted frame: the fresh rows' measured points in the blob's frame are R y + t.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RegisteredFrame {
    pub frame: Frame,
}

impl RegisteredFrame {
    /// t (data length unit), the rotation's axis and angle (degrees).
    pub fn to_json(&self) -> serde_json::Value {
        let (axis, angle) = axis_angle(&self.frame);
        serde_json::json!({"translation": self.frame.translation(), "axis": axis, "angle_deg": angle.to_degrees()})
    }
    /// "t = (…) mm, rotation 30.000° about (…)".
    pub fn describe(&self, unit: &str) -> String {
        let (axis, angle) = axis_angle(&self.frame);
        let t = self.frame.translation();
        format!(
            "t = ({:.4}, {:.4}, {:.4}) {unit}, rotation {:.4}° about ({:.4}, {:.4}, {:.4})",
            t[0],
            t[1],
            t[2],
            angle.to_degrees(),
            axis[0],
            axis[1],
            axis[2]
        )
    }
}

/// Registers `measured` (rows of 3 coordinates) onto `predicted`: the frame and the measured
/// points in the blob's frame. `None` for fewer than 3 rows or points on a line (no unique frame).
pub fn register(measured: &[f64], predicted: &[f64]) -> Option<(RegisteredFrame, Vec<f64>)> {
    let rows = |v: &[f64]| -> Vec<[f64; 3]> { v.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect() };
    let (y, p) = (rows(measured), rows(predicted));
    let frame = rigid_fit(&y, &p)?;
    if !spread_in_two_directions(&p) {
        return None;
    }
    let moved = y.iter().flat_map(|v| frame.apply(*v)).collect();
    Some((RegisteredFrame { frame }, moved))
}

/// T, (3 · rows) × 6: ∂x_i/∂t = I, ∂x_i/∂ω = −[x_i − x̄]×, the columns e_k × (x_i − x̄).
pub fn tangent(points: &[f64]) -> Mat<f64> {
    let rows = points.len() / 3;
    let mean: [f64; 3] = std::array::from_fn(|c| (0..rows).map(|i| points[3 * i + c]).sum::<f64>() / rows.max(1) as f64);
    Mat::from_fn(points.len(), FRAME_DOF, |r, k| {
        let (i, c) = (r / 3, r % 3);
        if k < 3 {
            return if c == k { 1.0 } else { 0.0 };
        }
        let x: [f64; 3] = std::array::from_fn(|a| points[3 * i + a] - mean[a]);
        let mut e = [0.0; 3];
        e[k - 3] = 1.0;
        crate::nominal::cross(e, x)[c]
    })
}

/// Whether the points span a plane at least (the rotation about a line through them is otherwise
/// undetermined): the second singular value of the centred points above 1e-9 of the first.
fn spread_in_two_directions(p: &[[f64; 3]]) -> bool {
    let n = p.len() as f64;
    let mean: [f64; 3] = std::array::from_fn(|c| p.iter().map(|x| x[c]).sum::<f64>() / n);
    let a = Mat::from_fn(p.len(), 3, |i, c| p[i][c] - mean[c]);
    a.singular_values().is_ok_and(|s| s.len() >= 2 && s[1] > 1e-9 * s[0].max(f64::MIN_POSITIVE))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A known motion (1 m, 30° about a skew axis) is recovered, and the tangent's rotation columns
    /// are the first-order change of R x under a small turn (a finite difference of Rodrigues).
    #[test]
    fn a_known_frame_is_recovered_and_the_tangent_is_its_derivative() {
        let p: Vec<f64> = (0..12)
            .flat_map(|i| {
                let t = i as f64;
                [300.0 * (0.7 * t).sin(), 250.0 * (1.3 * t).cos(), 40.0 * t]
            })
            .collect();
        let axis = {
            let v = [1.0, 2.0, -0.5];
            let n = crate::nominal::norm(v);
            crate::nominal::scale(v, 1.0 / n)
        };
        let tracker = crate::nominal::rotation_about(axis, 30f64.to_radians()).with_translation([600.0, -700.0, 400.0]);
        let measured: Vec<f64> = p.chunks_exact(3).flat_map(|c| tracker.apply([c[0], c[1], c[2]])).collect();
        let (frame, moved) = register(&measured, &p).unwrap();
        for (a, b) in moved.iter().zip(&p) {
            assert!((a - b).abs() < 1e-9, "{a} vs {b}");
        }
        let (_, angle) = axis_angle(&frame.frame);
        assert!((angle.to_degrees() - 30.0).abs() < 1e-9);
        let t = tangent(&p);
        let h = 1e-7;
        let mean: [f64; 3] = std::array::from_fn(|c| p.iter().skip(c).step_by(3).sum::<f64>() / 12.0);
        for k in 0..3 {
            let mut e = [0.0; 3];
            e[k] = 1.0;
            let turn = crate::nominal::rotation_about(e, h);
            for i in 0..12 {
                let x = crate::nominal::sub([p[3 * i], p[3 * i + 1], p[3 * i + 2]], mean);
                let d = crate::nominal::scale(crate::nominal::sub(turn.apply(x), x), 1.0 / h);
                for c in 0..3 {
                    assert!((t[(3 * i + c, 3 + k)] - d[c]).abs() < 1e-4 * (1.0 + d[c].abs()), "row {i} coordinate {c} column {k}");
                }
            }
        }
        // Points on a line leave a rotation undetermined.
        let line: Vec<f64> = (0..5).flat_map(|i| [i as f64, 2.0 * i as f64, 0.0]).collect();
        assert!(register(&line, &line).is_none());
    }
}

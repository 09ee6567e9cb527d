//! Rigid fits of point sets: the rigid motion that best carries one set of points onto another
//! (Kabsch/Horn) and a rotation's axis and angle. Pure geometry: the base registration on measured
//! data (`parametric::base_registration`) and the tool points' frames (`tool_points`) use them.

use super::Frame;

/// Axis and angle (radians) of a pose's rotation: angle from the trace, axis from the skew part.
pub fn axis_angle(p: &Frame) -> ([f64; 3], f64) {
    let r = p.rotation();
    let s = [r[2][1] - r[1][2], r[0][2] - r[2][0], r[1][0] - r[0][1]];
    let sin2 = super::norm(s);
    let cos = (r[0][0] + r[1][1] + r[2][2] - 1.0) / 2.0;
    let angle = sin2.atan2(2.0 * cos);
    if sin2 == 0.0 {
        return ([0.0, 0.0, 1.0], angle);
    }
    (super::scale(s, 1.0 / sin2), angle)
}

/// Kabsch/Horn: the rotation R and translation t minimising Σ |R p_i + t − y_i|² — R from the SVD
/// of the cross-covariance H = Σ (p_i − p̄)(y_i − ȳ)ᵀ = U Σ Vᵀ, R = V diag(1, 1, det(V Uᵀ)) Uᵀ,
/// t = ȳ − R p̄. `None` for fewer than 3 points or a degenerate SVD.
pub fn rigid_fit(p: &[[f64; 3]], y: &[[f64; 3]]) -> Option<Frame> {
    let n = p.len();
    if n < 3 || y.len() != n {
        return None;
    }
    let mean = |v: &[[f64; 3]]| -> [f64; 3] { std::array::from_fn(|c| v.iter().map(|x| x[c]).sum::<f64>() / n as f64) };
    let (pm, ym) = (mean(p), mean(y));
    let h = faer::Mat::<f64>::from_fn(3, 3, |a, b| p.iter().zip(y).map(|(pi, yi)| (pi[a] - pm[a]) * (yi[b] - ym[b])).sum());
    let svd = h.svd().ok()?;
    let (u, v) = (svd.U(), svd.V());
    let vu = |a: usize, b: usize, last: f64| -> f64 { (0..3).map(|k| v[(a, k)] * u[(b, k)] * if k == 2 { last } else { 1.0 }).sum() };
    let det = {
        let m: [[f64; 3]; 3] = std::array::from_fn(|a| std::array::from_fn(|b| vu(a, b, 1.0)));
        m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1]) - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
            + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
    };
    let sign = if det < 0.0 { -1.0 } else { 1.0 };
    let r: [[f64; 3]; 3] = std::array::from_fn(|a| std::array::from_fn(|b| vu(a, b, sign)));
    let rotated = Frame::new(r, [0.0; 3]).rotate(pm);
    let pose = Frame::new(r, std::array::from_fn(|c| ym[c] - rotated[c]));
    pose.iter().flatten().all(|v| v.is_finite()).then_some(pose)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rigid_fit_recovers_a_known_motion_and_refuses_too_few_points() {
        let motion = crate::nominal::rotation_about([0.6, 0.0, 0.8], 30f64.to_radians()).with_translation([4000.0, -1200.0, 300.0]);
        let p: Vec<[f64; 3]> = (0..20).map(|k| [(k as f64 * 0.7).sin() * 500.0, (k as f64 * 1.3).cos() * 400.0, k as f64 * 20.0]).collect();
        let y: Vec<[f64; 3]> = p.iter().map(|x| motion.apply(*x)).collect();
        let got = rigid_fit(&p, &y).unwrap();
        for i in 0..3 {
            assert!((got.translation()[i] - motion.translation()[i]).abs() < 1e-9, "{got:?}");
            for j in 0..3 {
                assert!((got.rotation()[i][j] - motion.rotation()[i][j]).abs() < 1e-12, "{got:?}");
            }
        }
        let (axis, angle) = axis_angle(&got);
        assert!((angle.to_degrees() - 30.0).abs() < 1e-9 && (axis[0] - 0.6).abs() < 1e-9 && (axis[2] - 0.8).abs() < 1e-9);
        // A reflection is never returned: a mirrored set gets the best proper rotation.
        let mirrored: Vec<[f64; 3]> = y.iter().map(|v| [-v[0], v[1], v[2]]).collect();
        let r = rigid_fit(&p, &mirrored).unwrap().rotation();
        let det = r[0][0] * (r[1][1] * r[2][2] - r[1][2] * r[2][1]) - r[0][1] * (r[1][0] * r[2][2] - r[1][2] * r[2][0])
            + r[0][2] * (r[1][0] * r[2][1] - r[1][1] * r[2][0]);
        assert!((det - 1.0).abs() < 1e-12);
        assert!(rigid_fit(&p[..2], &y[..2]).is_none());
    }
}

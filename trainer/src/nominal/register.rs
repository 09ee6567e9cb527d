//! Tracker frames: a base declared unknown (`[chain] base = { register = true }`) is registered
//! on the training data before anything else — the rigid motion that best carries the nominal
//! positions (base = identity) onto the measured ones (Kabsch/Horn) — so that "nominal" means
//! nominal in the registered frame. `parametric::register` refines it with the geometric group
//! (the pipelines call that); the DH and diagnose pipelines then fit the base with the rest of the
//! geometric group, as they do a declared one.

use super::Frame;
use crate::data::Measurements;
use cbd_protocol::NominalModel;

/// A registered base and what it did.
#[derive(Debug, Clone, PartialEq)]
pub struct Registration {
    /// The base (model length unit, rotation as a matrix).
    pub base: Frame,
    /// RMS distance of the nominal positions from the measured ones with the declared (identity)
    /// base, and with the registered one.
    pub rms_before: f64,
    pub rms_after: f64,
    /// Whether the rigid fit was refined by the geometric group (`parametric::register`).
    pub refined: bool,
    /// The refinement stopped at its iteration limit (this many iterations) without converging:
    /// every loop after registration is bounded, and a bound hit is said.
    pub stopped_at_limit: Option<usize>,
}

impl Registration {
    /// One line: translation, rotation as axis and angle (degrees), RMS before and after.
    pub fn describe(&self, unit: &str) -> String {
        let (axis, angle) = axis_angle(&self.base);
        let t = self.base.translation();
        format!(
            "registered base{}: translation [{:.6}, {:.6}, {:.6}] {unit}, rotation {:.6}° about [{:.6}, {:.6}, {:.6}]; nominal RMS {:.4e} → {:.4e} {unit}",
            if self.refined { " (rigid fit refined by the geometric group)" } else { " (rigid fit)" },
            t[0],
            t[1],
            t[2],
            angle.to_degrees(),
            axis[0],
            axis[1],
            axis[2],
            self.rms_before,
            self.rms_after
        ) + &match self.stopped_at_limit {
            Some(n) => format!(" (the refinement stopped at its limit of {n} iterations without converging)"),
            None => String::new(),
        }
    }
}

impl Registration {
    /// `{"translation": [..], "rotation": [[..], ..], "axis": [..], "angle_deg", "rms_before", "rms_after"}`
    /// (model length unit).
    pub fn to_json(&self) -> serde_json::Value {
        let (axis, angle) = axis_angle(&self.base);
        serde_json::json!({"translation": self.base.translation(), "rotation": self.base.rotation(), "axis": axis, "angle_deg": angle.to_degrees(),
                           "rms_before": self.rms_before, "rms_after": self.rms_after, "refined": self.refined,
                           "stopped_at_limit": self.stopped_at_limit})
    }
}

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

/// RMS distance of `chain`'s nominal positions from the measured ones.
pub fn rms_from(chain: &cbd_protocol::DhChain, data: &Measurements) -> f64 {
    let model = NominalModel::DhChain(chain.clone());
    let s: f64 = (0..data.len())
        .map(|i| {
            let p = super::row_kinematics(&model, data.joints(i), i).position;
            (0..3).map(|c| (p[c] - data.position(i)[c]).powi(2)).sum::<f64>()
        })
        .sum();
    (s / data.len().max(1) as f64).sqrt()
}

/// Registers the base of `nominal` (a DH chain whose base is the identity) on `data`: the base
/// becomes the rigid fit of its positions to the measured ones.
pub fn register_base(nominal: &mut NominalModel, data: &Measurements) -> Result<Registration, RegisterError> {
    let NominalModel::DhChain(chain) = nominal else {
        return Err(RegisterError::NotADhChain);
    };
    let model = NominalModel::DhChain(chain.clone());
    let p: Vec<[f64; 3]> = (0..data.len()).map(|i| super::row_kinematics(&model, data.joints(i), i).position).collect();
    let y: Vec<[f64; 3]> = (0..data.len()).map(|i| std::array::from_fn(|c| data.position(i)[c])).collect();
    check_geometry(&p, &y)?;
    let base = rigid_fit(&p, &y).ok_or(RegisterError::Degenerate { rows: data.len() })?;
    let declared = Frame::from_transform(&chain.base);
    let rms_before = rms_from(chain, data);
    chain.base = base.compose(&declared).to_transform();
    Ok(Registration { rms_before, rms_after: rms_from(chain, data), base: base.compose(&declared), refined: false, stopped_at_limit: None })
}

/// Refuses what determines no rigid motion, before any fit: measured (or nominal) positions that
/// are one point or on one line (the rotation about the line is free), and measurements that are
/// a mirror image of the nominal positions (no rotation carries one onto the other; a fit over
/// such a frame ran for minutes and meant nothing).
fn check_geometry(p: &[[f64; 3]], y: &[[f64; 3]]) -> Result<(), RegisterError> {
    use cbd_runtime::kinematics::tool_frame::determines_orientation;
    for (what, points) in [("measured", y), ("nominal", p)] {
        // Far from the origin f64 keeps fewer of the spread's digits (1e50 mm away: none).
        let magnitude = points.iter().flatten().fold(0.0f64, |m, v| m.max(v.abs()));
        let (lo, hi) = points.iter().fold(([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]), |(lo, hi), v| {
            (std::array::from_fn(|c| lo[c].min(v[c])), std::array::from_fn(|c| hi[c].max(v[c])))
        });
        let extent = (0..3).map(|c| hi[c] - lo[c]).fold(0.0, f64::max);
        let one_point = points.iter().all(|q| *q == points[0]);
        if points.len() >= 3 && !one_point && extent < RESOLVED_DIGITS * f64::EPSILON * magnitude {
            return Err(RegisterError::Unresolved { what, magnitude, extent });
        }
        if points.len() >= 3 && !determines_orientation(points) {
            return Err(if one_point { RegisterError::OnePoint { what, magnitude } } else { RegisterError::OnALine { what } });
        }
    }
    let rms = |fit: Option<Frame>, y: &[[f64; 3]]| {
        fit.map_or(f64::INFINITY, |f| {
            (p.iter().zip(y).map(|(a, b)| super::norm(super::sub(f.apply(*a), *b)).powi(2)).sum::<f64>() / p.len().max(1) as f64).sqrt()
        })
    };
    let mirrored: Vec<[f64; 3]> = y.iter().map(|v| [-v[0], v[1], v[2]]).collect();
    let (rotation, reflection) = (rms(rigid_fit(p, y), y), rms(rigid_fit(p, &mirrored), &mirrored));
    let mean: [f64; 3] = std::array::from_fn(|c| y.iter().map(|v| v[c]).sum::<f64>() / y.len().max(1) as f64);
    let spread = (y.iter().map(|v| super::norm(super::sub(*v, mean)).powi(2)).sum::<f64>() / y.len().max(1) as f64).sqrt();
    if rotation > 2.0 * reflection && rotation > 1e-3 * spread {
        return Err(RegisterError::Mirrored { rotation, reflection });
    }
    Ok(())
}

/// The positions' extent must be at least this many times their resolution in f64 (ε × their
/// magnitude): six digits of the arm's shape kept (1000 km from the origin a 1 m arm keeps 0.2 µm).
const RESOLVED_DIGITS: f64 = 1e6;

/// Why [`register_base`] could not register the base.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RegisterError {
    #[error("registering the base needs a [chain] or [urdf] arm (a [planar] file gives base and yaw)")]
    NotADhChain,
    /// No rigid motion is determined by the data's positions.
    #[error("cannot register the base on {rows} rows (at least 3 in general position needed)")]
    Degenerate { rows: usize },
    /// The positions are so far from the origin that f64 no longer resolves their extent.
    #[error("cannot register the base: the {what} positions are up to {} from the origin, where f64 resolves only {}: their extent {} is lost to rounding (move the tracker's origin nearer the arm)", crate::error::number(*magnitude), crate::error::number(*magnitude * f64::EPSILON), crate::error::number(*extent))]
    Unresolved { what: &'static str, magnitude: f64, extent: f64 },
    /// Every position is the same point (to f64's precision at their magnitude).
    #[error("cannot register the base: the {what} positions are all one point (largest coordinate {}): no rotation is determined", crate::error::number(*magnitude))]
    OnePoint { what: &'static str, magnitude: f64 },
    /// The positions lie on one line: the rotation about it is free.
    #[error("cannot register the base: the {what} positions lie on one line, so the rotation about it is undetermined (measure poses that spread in two directions at least)")]
    OnALine { what: &'static str },
    /// The measurements are a mirror image of the nominal positions.
    #[error("cannot register the base: the measurements are a mirror image of the nominal model's positions — the best rotation leaves {} RMS, a reflection {} (a left-handed tracker frame, or a coordinate's sign flipped?)", crate::error::number(*rotation), crate::error::number(*reflection))]
    Mirrored { rotation: f64, reflection: f64 },
}

impl From<RegisterError> for crate::Error {
    fn from(e: RegisterError) -> crate::Error {
        crate::Error::stage("base registration", e)
    }
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

    /// Issue 39 case 7: mirrored or collinear tracker data were registered anyway and the fits over
    /// the meaningless frame ran for minutes. Each is refused up front with its reason.
    #[test]
    fn degenerate_geometry_is_refused_with_its_reason() {
        let motion = crate::nominal::rotation_about([0.6, 0.0, 0.8], 0.4).with_translation([4000.0, -1200.0, 300.0]);
        let p: Vec<[f64; 3]> = (0..20).map(|k| [(k as f64 * 0.7).sin() * 500.0, (k as f64 * 1.3).cos() * 400.0, k as f64 * 20.0]).collect();
        let y: Vec<[f64; 3]> = p.iter().map(|x| motion.apply(*x)).collect();
        check_geometry(&p, &y).unwrap();
        let mirrored: Vec<[f64; 3]> = y.iter().map(|v| [v[0], -v[1], v[2]]).collect();
        assert!(matches!(check_geometry(&p, &mirrored), Err(RegisterError::Mirrored { .. })));
        let line: Vec<[f64; 3]> = (0..20).map(|k| [k as f64, 2.0 * k as f64, 3.0]).collect();
        let e = check_geometry(&p, &line).unwrap_err().to_string();
        assert!(e.contains("measured positions lie on one line"), "{e}");
        let far: Vec<[f64; 3]> = y.iter().map(|v| [v[0] + 1e50, v[1], v[2]]).collect();
        let e = check_geometry(&p, &far).unwrap_err().to_string();
        assert!(e.contains("measured positions are up to 1e50 from the origin, where f64 resolves only 2.2204e34"), "{e}");
        let resolved: Vec<[f64; 3]> = y.iter().map(|v| [v[0] + 1e9, v[1], v[2]]).collect();
        check_geometry(&p, &resolved).unwrap();
        let e = check_geometry(&vec![[1.0, 2.0, 3.0]; 20], &y).unwrap_err().to_string();
        assert!(e.contains("nominal positions are all one point (largest coordinate 3)"), "{e}");
    }
}

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
        )
    }
}

impl Registration {
    /// `{"translation": [..], "rotation": [[..], ..], "axis": [..], "angle_deg", "rms_before", "rms_after"}`
    /// (model length unit).
    pub fn to_json(&self) -> serde_json::Value {
        let (axis, angle) = axis_angle(&self.base);
        serde_json::json!({"translation": self.base.translation(), "rotation": self.base.rotation(), "axis": axis, "angle_deg": angle.to_degrees(),
                           "rms_before": self.rms_before, "rms_after": self.rms_after, "refined": self.refined})
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
    let base = rigid_fit(&p, &y).ok_or(RegisterError::Degenerate { rows: data.len() })?;
    let declared = Frame::from_transform(&chain.base);
    let rms_before = rms_from(chain, data);
    chain.base = base.compose(&declared).to_transform();
    Ok(Registration { rms_before, rms_after: rms_from(chain, data), base: base.compose(&declared), refined: false })
}

/// Why [`register_base`] could not register the base.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RegisterError {
    #[error("registering the base needs a [chain] or [urdf] arm (a [planar] file gives base and yaw)")]
    NotADhChain,
    /// No rigid motion is determined by the data's positions.
    #[error("cannot register the base on {rows} rows (at least 3 in general position needed)")]
    Degenerate { rows: usize },
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
}

//! Tracker frames: a base declared unknown (`[chain] base = { register = true }`) is registered
//! on the training data before anything else, in two steps.
//!
//! First the rigid motion that best carries the nominal positions (base = identity) onto the
//! measured ones (Kabsch/Horn, `nominal::rigid_fit`: [`register_base`]), so that "nominal" means
//! nominal in the registered frame. Then that rigid registration refined by the geometric group
//! ([`register_and_refine`], what the pipelines call); the DH and diagnose pipelines then fit the
//! base with the rest of the geometric group, as they do a declared one.
//!
//! The rigid fit of the nominal positions to the measured ones also takes up
//! whatever of the arm's DH errors looks rigid (0.02–0.2 mm and 0.01–0.03° off the true joint-1
//! axis on the simulated six-joint arm); fitting every DH parameter, the base and the tool
//! together separates them, and the base is what remains of that fit once joint 1's constant
//! part is folded into it.
//!
//! The fold: joint 1's transform is P ∘ Rz(q₁ + θ₁) ∘ Tz(d₁) (P = identity in standard DH,
//! Rx(α₀) Tx(a₀) in Craig's), and Rz(Δθ) Tz(Δd) commutes with Rz(q₁ + θ₁) Tz(d₁), so
//! B ∘ P' ∘ Rz(q₁ + θ₁') Tz(d₁') = [B ∘ P' ∘ Rz(θ₁' − θ₁) Tz(d₁' − d₁) ∘ P⁻¹] ∘ P ∘ Rz(q₁ + θ₁) Tz(d₁)
//! exactly: the bracket is the base that, with the nominal joint 1, places joint 1's frame where
//! the calibration put it. Base yaw vs θ₁ and base z vs d₁ cannot be told apart by any data;
//! the fold makes the answer independent of which member the calibration kept.

use super::{calibrate_dh, DhCalibrationOptions};
use crate::data::Measurements;
use crate::nominal::rigid_fit::{axis_angle, rigid_fit};
use crate::nominal::{norm, rotation_about, row_kinematics, sub, Frame};
use cbd_protocol::{DhChain, DhConvention, DhJoint, NominalModel};

/// A registered base and what it did.
#[derive(Debug, Clone, PartialEq)]
pub struct Registration {
    /// The base (model length unit, rotation as a matrix).
    pub base: Frame,
    /// RMS distance of the nominal positions from the measured ones with the declared (identity)
    /// base, and with the registered one.
    pub rms_before: f64,
    pub rms_after: f64,
    /// Whether the rigid fit was refined by the geometric group ([`register_and_refine`]).
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

/// RMS distance of `chain`'s nominal positions from the measured ones.
pub fn rms_from(chain: &cbd_protocol::DhChain, data: &Measurements) -> f64 {
    let model = NominalModel::DhChain(chain.clone());
    let s: f64 = (0..data.len())
        .map(|i| {
            let p = row_kinematics(&model, data.joints(i), i).position;
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
    let p: Vec<[f64; 3]> = (0..data.len()).map(|i| row_kinematics(&model, data.joints(i), i).position).collect();
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
    use cbd_runtime::internals::kinematics::tool_frame::determines_orientation;
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
            (p.iter().zip(y).map(|(a, b)| norm(sub(f.apply(*a), *b)).powi(2)).sum::<f64>() / p.len().max(1) as f64).sqrt()
        })
    };
    let mirrored: Vec<[f64; 3]> = y.iter().map(|v| [-v[0], v[1], v[2]]).collect();
    let (rotation, reflection) = (rms(rigid_fit(p, y), y), rms(rigid_fit(p, &mirrored), &mirrored));
    let mean: [f64; 3] = std::array::from_fn(|c| y.iter().map(|v| v[c]).sum::<f64>() / y.len().max(1) as f64);
    let spread = (y.iter().map(|v| norm(sub(*v, mean)).powi(2)).sum::<f64>() / y.len().max(1) as f64).sqrt();
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

/// Joint 1's constant part before its rotation: P (identity in standard DH, Rx(α) Tx(a) in Craig's).
fn before_joint(convention: DhConvention, joint: &DhJoint) -> Frame {
    match convention {
        DhConvention::Standard => Frame::IDENTITY,
        DhConvention::Modified => {
            rotation_about([1.0, 0.0, 0.0], joint.alpha).compose(&Frame::IDENTITY.with_translation([joint.a, 0.0, 0.0]))
        }
    }
}

/// The base that, with `nominal`'s joint 1, puts joint 1's frame where `calibrated` puts it
/// (the fold of the module's comment).
pub fn folded_base(nominal: &DhChain, calibrated: &DhChain) -> Frame {
    let base = Frame::from_transform(&calibrated.base);
    let (Some(j0), Some(j1)) = (nominal.joints.first(), calibrated.joints.first()) else { return base };
    let shift = rotation_about([0.0, 0.0, 1.0], j1.theta_offset - j0.theta_offset).with_translation([0.0, 0.0, j1.d - j0.d]);
    base.compose(&before_joint(calibrated.convention, j1)).compose(&shift).compose(&before_joint(nominal.convention, j0).inverse())
}

/// Registers the base of `nominal` on `data` (rigid fit, [`register_base`]) and
/// refines it by the geometric group (DH calibration of every parameter, base and tool; the base
/// folded as in the module's comment). When the calibration cannot run (too few rows) the rigid
/// registration stands and `refined` says so.
pub fn register_and_refine(nominal: &mut NominalModel, data: &Measurements) -> Result<Registration, RegisterError> {
    let rigid = register_base(nominal, data)?;
    let NominalModel::DhChain(chain) = &*nominal else { return Ok(rigid) };
    let Ok(calibration) = calibrate_dh(nominal, data, &DhCalibrationOptions::default()) else { return Ok(rigid) };
    let NominalModel::DhChain(calibrated) = &calibration.model else { return Ok(rigid) };
    let base = folded_base(chain, calibrated);
    if !base.iter().flatten().all(|v| v.is_finite()) {
        return Ok(rigid);
    }
    let mut refined = chain.clone();
    refined.base = base.to_transform();
    let stats = &calibration.stats;
    let registration = Registration {
        base,
        rms_before: rigid.rms_before,
        rms_after: rms_from(&refined, data),
        refined: true,
        stopped_at_limit: (!stats.converged).then_some(stats.iterations),
    };
    *nominal = NominalModel::DhChain(refined);
    Ok(registration)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn chain(convention: DhConvention) -> DhChain {
        let NominalModel::DhChain(mut c) = crate::simulate::six_joint::SixJointRobot::ur5_like(3).nominal else { unreachable!() };
        c.convention = convention;
        c.joints[0].a = 40.0;
        c.joints[0].alpha = 0.3;
        c
    }

    /// The fold is exact: the nominal joint 1 on the folded base walks to the same frames as the
    /// calibrated joint 1 on the calibrated base, in both conventions, for any q₁.
    #[test]
    fn folded_base_with_the_nominal_joint_one_reproduces_the_calibrated_chain() {
        for convention in [DhConvention::Standard, DhConvention::Modified] {
            let nominal = chain(convention);
            let mut calibrated = nominal.clone();
            calibrated.base = rotation_about([0.36, 0.48, 0.8], 0.02)
                .with_translation([1.5, -0.7, 2.0])
                .compose(&Frame::from_transform(&nominal.base))
                .to_transform();
            calibrated.joints[0].theta_offset += 0.004;
            calibrated.joints[0].d -= 0.8;
            if convention == DhConvention::Modified {
                calibrated.joints[0].alpha += 0.001;
                calibrated.joints[0].a += 0.3;
            }
            let mut folded = nominal.clone();
            folded.base = folded_base(&nominal, &calibrated).to_transform();
            // Only the base and joint 1's folded parameters differ: the other joints stay nominal.
            for q1 in [-2.0, 0.0, 0.7, 3.0] {
                let q = [q1, -1.0, 0.5, 0.2, 1.1, -0.4];
                let want = cbd_runtime::internals::kinematics::rigid::dh_walk(&calibrated, &q);
                let got = cbd_runtime::internals::kinematics::rigid::dh_walk(&folded, &q);
                for (a, b) in want.ends.iter().zip(&got.ends) {
                    for k in 0..3 {
                        assert!((a[k] - b[k]).abs() < 1e-9, "{convention:?} q1 = {q1}: {a:?} vs {b:?}");
                    }
                }
            }
            let (_, angle) = axis_angle(&Frame::from_transform(&folded.base).inverse().compose(&Frame::from_transform(&nominal.base)));
            assert!(angle > 0.01, "the fold moved the base");
        }
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

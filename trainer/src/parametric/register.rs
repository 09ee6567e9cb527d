//! Tracker frames, second step: the rigid registration (`nominal::register`) refined by the
//! geometric group. The rigid fit of the nominal positions to the measured ones also takes up
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
use crate::nominal::register::{register_base, RegisterError, Registration};
use crate::nominal::{rotation_about, Frame};
use cbd_protocol::{DhChain, DhConvention, DhJoint, NominalModel};

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

/// Registers the base of `nominal` on `data` (rigid fit, `nominal::register::register_base`) and
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
        rms_after: crate::nominal::register::rms_from(&refined, data),
        refined: true,
        stopped_at_limit: (!stats.converged).then_some(stats.iterations),
    };
    *nominal = NominalModel::DhChain(refined);
    Ok(registration)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::nominal::register::axis_angle;
    use crate::nominal::Frame;

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
                let want = cbd_runtime::kinematics::rigid::dh_walk(&calibrated, &q);
                let got = cbd_runtime::kinematics::rigid::dh_walk(&folded, &q);
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
}

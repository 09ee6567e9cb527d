//! Planted changes of the real arm's geometry (issue 50's `cbd simulate --effect` types), for
//! drawing a calibration set and a changed set from the same arm: a joint's zero, the base, the
//! tool, a link's length, a uniform length scale (temperature). Each changes the real DH chain
//! before it is measured; the arm keeps its other errors and its built-in joint compliance.

use crate::effects::{EffectSpecError, Spec};
use cbd_protocol::DhChain;

/// The `--effect` types this module plants.
pub const PLANTED: [&str; 6] = ["joint_zero", "base_shift", "tool_shift", "link_length", "link_twist", "length_scale"];

/// One planted change.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Planted {
    /// θ_J = q_J + theta_offset + offset: the joint reads `offset` radians less at the same pose.
    JointZero { joint: usize, offset: f64 },
    /// The base frame moves by d (the world frame, the model's length unit).
    BaseShift([f64; 3]),
    /// The tool point moves by d in the flange's (last DH) frame.
    ToolShift([f64; 3]),
    /// Link L's DH length a grows by `delta`.
    LinkLength { link: usize, delta: f64 },
    /// Link L's DH twist α grows by `delta` radians (a bent link; `cbd check` names it).
    LinkTwist { link: usize, delta: f64 },
    /// Every length of the chain (a, d, base and tool translations) × `scale`.
    LengthScale(f64),
}

/// `Some` when `spec` is one of [`PLANTED`]: its change, or why it is malformed.
pub fn parse_planted(spec: &str, n_joints: usize) -> Option<Result<Planted, EffectSpecError>> {
    let (kind, s) = match Spec::parse(spec, n_joints) {
        Ok(v) => v,
        Err(e) => return PLANTED.iter().any(|k| spec.starts_with(k)).then_some(Err(e)),
    };
    if !PLANTED.contains(&kind.as_str()) {
        return None;
    }
    let shift = |s: &Spec| -> Result<[f64; 3], EffectSpecError> {
        Ok([s.number("dx", Some(0.0))?, s.number("dy", Some(0.0))?, s.number("dz", Some(0.0))?])
    };
    let planted = (|| match kind.as_str() {
        "joint_zero" => Ok(Planted::JointZero { joint: s.index("joint")?, offset: s.number("offset", None)? }),
        "base_shift" => Ok(Planted::BaseShift(shift(&s)?)),
        "tool_shift" => Ok(Planted::ToolShift(shift(&s)?)),
        "link_length" => Ok(Planted::LinkLength { link: s.index("link")?, delta: s.number("delta", None)? }),
        "link_twist" => Ok(Planted::LinkTwist { link: s.index("link")?, delta: s.number("delta", None)? }),
        _ => {
            let scale = s.number("scale", None)?;
            if scale <= 0.0 {
                return Err(s.bad(format!("scale = {} must be positive", crate::error::number(scale))));
            }
            Ok(Planted::LengthScale(scale))
        }
    })();
    Some(planted.and_then(|p| s.check_all_read().map(|()| p)))
}

impl Planted {
    /// The chain with this change.
    pub fn apply(&self, chain: &mut DhChain) {
        match *self {
            Planted::JointZero { joint, offset } => chain.joints[joint].theta_offset += offset,
            Planted::BaseShift(d) => (0..3).for_each(|c| chain.base.translation[c] += d[c]),
            Planted::ToolShift(d) => (0..3).for_each(|c| chain.tool.translation[c] += d[c]),
            Planted::LinkLength { link, delta } => chain.joints[link].a += delta,
            Planted::LinkTwist { link, delta } => chain.joints[link].alpha += delta,
            Planted::LengthScale(s) => {
                for j in chain.joints.iter_mut() {
                    j.a *= s;
                    j.d *= s;
                }
                (0..3).for_each(|c| {
                    chain.base.translation[c] *= s;
                    chain.tool.translation[c] *= s;
                });
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::simulate::six_joint::ur5_nominal;

    /// Each change moves the tool point as its geometry says, checked on the UR5 chain's forward
    /// kinematics: a base shift by d everywhere, a length scale s scales every position about the
    /// base origin (the base at the origin), a joint-1 zero turns the point about the base z axis.
    #[test]
    fn planted_changes_move_the_tool_point_as_their_geometry_says() {
        let position = |c: &DhChain, q: &[f64]| crate::nominal::positions(&cbd_protocol::NominalModel::DhChain(c.clone()), q, 3);
        let q = [0.3, -1.1, 0.8, 0.2, -0.5, 1.4];
        let base = ur5_nominal();
        let p0 = position(&base, &q);
        let changed = |spec: &str| {
            let mut c = base.clone();
            parse_planted(spec, 6).unwrap().unwrap().apply(&mut c);
            position(&c, &q)
        };
        let p = changed("base_shift:dx=0.5,dz=-0.25");
        assert!((p[0] - p0[0] - 0.5).abs() < 1e-9 && (p[1] - p0[1]).abs() < 1e-9 && (p[2] - p0[2] + 0.25).abs() < 1e-9);
        let p = changed("length_scale:scale=1.001");
        for c in 0..3 {
            assert!((p[c] - 1.001 * p0[c]).abs() < 1e-9, "{c}");
        }
        let p = changed("joint_zero:joint=1,offset=0.01");
        let (s, co) = 0.01f64.sin_cos();
        assert!((p[0] - (co * p0[0] - s * p0[1])).abs() < 1e-9 && (p[2] - p0[2]).abs() < 1e-9);
        let p = changed("tool_shift:dz=2");
        let d: f64 = (0..3).map(|c| (p[c] - p0[c]).powi(2)).sum::<f64>().sqrt();
        assert!((d - 2.0).abs() < 1e-9, "{d}");
        assert!(parse_planted("joint_zero:joint=1,offset=0", 6).unwrap().is_ok(), "offset 0 allowed");
        assert!(parse_planted("link_length:link=7,delta=1", 6).unwrap().is_err());
        let mut c = base.clone();
        parse_planted("link_twist:link=2,delta=1e-3", 6).unwrap().unwrap().apply(&mut c);
        assert!((c.joints[1].alpha - base.joints[1].alpha - 1e-3).abs() < 1e-15);
        assert!(parse_planted("length_scale:scale=1,oops=2", 6).unwrap().is_err());
        assert!(parse_planted("encoder_scale:joint=1,scale=1", 6).is_none());
    }
}

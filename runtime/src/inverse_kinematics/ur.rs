//! Closed-form inverse kinematics of UR-type arms: six revolute joints, standard DH with
//! α = (π/2, 0, 0, π/2, −π/2, 0) and a1 = a4 = a5 = a6 = 0 (three parallel axes 2–4, wrist
//! offsets d4, d5, d6). For a tool pose there are up to eight solutions: two shoulders (θ1), two
//! wrists (θ5), two elbows (θ3).
//!
//! With T = base⁻¹ · pose · tool⁻¹ the flange pose (rotation R, position p6), o5 = p6 − d6 z6 and
//! z1 = (sin θ1, −cos θ1, 0):
//!
//! ```text
//! z1 · o5 = d2 + d3 + d4                      ⇒ θ1 = atan2(o5y, o5x) + { asin(D/ρ), π − asin(D/ρ) },  ρ = |o5,xy|
//! z1 · p6 = D + d6 cos θ5                      ⇒ θ5 = ± acos((z1 · p6 − D)/d6)
//! x6 · z1 = sin θ5 cos θ6,  y6 · z1 = −sin θ5 sin θ6   ⇒ θ6
//! T14 = T01⁻¹ T T56⁻¹ T45⁻¹: planar 2R in frame 1 (a2, a3) ⇒ θ3 = ± acos(…), θ2; θ4 = ∠x4 − θ2 − θ3
//! ```
//!
//! and q_i = θ_i − theta_offset_i.

use crate::kinematics::rigid::{dh_transform, dh_walk};
use crate::kinematics::spatial::Frame;
use cbd_protocol::{DhChain, DhConvention, JointKind};
// The tests (`use super::*`) give their chains a `Transform` base, as before the pose became a `Frame`.
#[cfg(test)]
use cbd_protocol::Transform;

/// A tool pose in the base frame: a [`Frame`] (the runtime's one rigid-transform type).
pub type Pose = Frame;

/// One solution slot: the joints, or `None` where that branch does not exist for the pose.
pub type Solutions = [Option<[f64; 6]>; 8];

/// T_i = Rz(θ) Tz(d) Tx(a) Rx(α) (standard DH), the DH walk's product.
fn dh(theta: f64, d: f64, a: f64, alpha: f64) -> Frame {
    dh_transform(DhConvention::Standard, theta, d, a, alpha)
}

/// Whether `chain` is UR-type (see the module doc): then [`solutions`] applies.
pub fn is_ur_type(chain: &DhChain) -> bool {
    use core::f64::consts::FRAC_PI_2;
    const ALPHA: [f64; 6] = [FRAC_PI_2, 0.0, 0.0, FRAC_PI_2, -FRAC_PI_2, 0.0];
    if chain.convention != DhConvention::Standard || chain.joints.len() != 6 || !chain.effects.is_empty() {
        return false;
    }
    let scale = chain.joints.iter().fold(0.0f64, |s, j| s.max(j.a.abs()).max(j.d.abs()));
    let zero_a = |i: usize| chain.joints.get(i).map(|j| j.a.abs() <= 1e-12 * scale).unwrap_or(false);
    chain.joints.iter().all(|j| j.kind == JointKind::Revolute)
        && chain.joints.iter().zip(ALPHA).all(|(j, a)| (j.alpha - a).abs() <= 1e-12)
        && zero_a(0)
        && zero_a(3)
        && zero_a(4)
        && zero_a(5)
        && chain.joints.get(1).map(|j| j.a.abs() > 0.0).unwrap_or(false)
        && chain.joints.get(2).map(|j| j.a.abs() > 0.0).unwrap_or(false)
        && chain.joints.get(5).map(|j| j.d.abs() > 0.0).unwrap_or(false)
}

/// The full tool pose (base frame, tool included) of a DH chain at joints `q`: the DH walk's tool frame.
pub fn tool_pose(chain: &DhChain, q: &[f64]) -> Pose {
    let walk = dh_walk(chain, q);
    Frame::new(walk.tool_rotation, walk.tool)
}

/// The eight closed-form solutions for the tool `pose` (base frame), in the order
/// (shoulder, wrist, elbow) = (±, ±, ±) with `+` first; `None` for branches the pose does not
/// admit (out of reach). At a wrist singularity (sin θ5 = 0) θ6 is set to 0 (any θ6 with the
/// matching θ4 is a solution). Joints are in (−π, π] before the offsets are subtracted. Not
/// UR-type or non-finite pose: all `None`.
pub fn solutions(chain: &DhChain, pose: &Pose) -> Solutions {
    let mut out: Solutions = [None; 8];
    if !is_ur_type(chain) || pose.iter().flatten().any(|v| !v.is_finite()) {
        return out;
    }
    let p = |i: usize| chain.joints.get(i).copied();
    let (Some(j1), Some(j2), Some(j3), Some(j4), Some(j5), Some(j6)) = (p(0), p(1), p(2), p(3), p(4), p(5)) else {
        return out;
    };
    let flange = Frame::from_transform(&chain.base).inverse().compose(pose).compose(&Frame::from_transform(&chain.tool).inverse());
    let (d1, a2, a3, d5, d6) = (j1.d, j2.a, j3.a, j5.d, j6.d);
    let offset_sum = j2.d + j3.d + j4.d;
    // Rows [R_i0, R_i1, R_i2, p6_i]: x6, y6, z6 are R's columns.
    let Frame([[x6x, y6x, z6x, p6x], [x6y, y6y, z6y, p6y], [_, _, z6z, p6z]]) = flange;
    let p6 = [p6x, p6y, p6z];
    let z6 = [z6x, z6y, z6z];
    let o5 = [p6[0] - d6 * z6[0], p6[1] - d6 * z6[1]];
    let rho = libm::hypot(o5[0], o5[1]);
    if !(rho >= offset_sum.abs()) || rho == 0.0 {
        return out;
    }
    let phi = libm::atan2(o5[1], o5[0]);
    let psi = libm::asin(offset_sum / rho);
    let mut slot = 0;
    for theta1 in [phi + psi, phi + core::f64::consts::PI - psi] {
        let (s1, c1) = (libm::sin(theta1), libm::cos(theta1));
        let cos5 = (p6[0] * s1 - p6[1] * c1 - offset_sum) / d6;
        let wrist_ok = (-1.0 - 1e-12..=1.0 + 1e-12).contains(&cos5);
        let acos5 = libm::acos(cos5.clamp(-1.0, 1.0));
        for theta5 in [acos5, -acos5] {
            let s5 = libm::sin(theta5);
            // x6 · z1 = sin θ5 cos θ6, y6 · z1 = −sin θ5 sin θ6.
            let x6z1 = x6x * s1 - x6y * c1;
            let y6z1 = y6x * s1 - y6y * c1;
            let theta6 = if s5.abs() < 1e-12 { 0.0 } else { libm::atan2(-y6z1 / s5, x6z1 / s5) };
            // T14 = T01⁻¹ T T56⁻¹ T45⁻¹.
            let t01 = dh(theta1, d1, j1.a, j1.alpha);
            let t45 = dh(theta5, d5, j5.a, j5.alpha);
            let t56 = dh(theta6, d6, j6.a, j6.alpha);
            let t14 = t01.inverse().compose(&flange).compose(&t45.compose(&t56).inverse());
            let Frame([[x4x, _, _, x], [x4y, _, _, y], _]) = t14;
            let cos3 = (x * x + y * y - a2 * a2 - a3 * a3) / (2.0 * a2 * a3);
            let elbow_ok = (-1.0 - 1e-12..=1.0 + 1e-12).contains(&cos3);
            let acos3 = libm::acos(cos3.clamp(-1.0, 1.0));
            for theta3 in [acos3, -acos3] {
                let (s3, c3) = (libm::sin(theta3), libm::cos(theta3));
                let theta2 = libm::atan2(y, x) - libm::atan2(a3 * s3, a2 + a3 * c3);
                // x4 in frame 1 is (cos θ234, sin θ234, 0).
                let theta4 = libm::atan2(x4y, x4x) - theta2 - theta3;
                if let Some(s) = out.get_mut(slot) {
                    if wrist_ok && elbow_ok {
                        let thetas = [theta1, theta2, theta3, theta4, theta5, theta6];
                        let mut q = [0.0; 6];
                        for ((qi, th), j) in q.iter_mut().zip(thetas).zip(chain.joints.iter()) {
                            *qi = wrap(th - j.theta_offset);
                        }
                        *s = Some(q);
                    }
                }
                slot += 1;
            }
        }
    }
    out
}

/// The angle in (−π, π].
fn wrap(a: f64) -> f64 {
    let two_pi = 2.0 * core::f64::consts::PI;
    let w = a - libm::round(a / two_pi) * two_pi;
    if w <= -core::f64::consts::PI {
        w + two_pi
    } else {
        w
    }
}

/// The solution for the tool at `target` with the orientation the tool has at `hint`, nearest
/// to `hint` (sum of squared angle differences modulo 2π; whole turns taken from the hint).
/// `None` when the chain is not UR-type or no branch reaches.
pub fn nearest_to_hint(chain: &DhChain, target: &[f64; 3], hint: &[f64; 6]) -> Option<[f64; 6]> {
    let pose = tool_pose(chain, hint).with_translation(*target);
    nearest_solution(solutions(chain, &pose), hint)
}

/// Of the closed-form `solutions`, the one nearest `hint` (sum of squared angle differences, whole
/// turns taken from the hint); `None` when no branch reaches.
pub fn nearest_solution(solutions: Solutions, hint: &[f64; 6]) -> Option<[f64; 6]> {
    let mut best: Option<(f64, [f64; 6])> = None;
    for q in solutions.into_iter().flatten() {
        let mut near = q;
        let mut distance = 0.0;
        for (n, h) in near.iter_mut().zip(hint) {
            *n += super::nearest_turn(*h - *n);
            distance += (*n - h) * (*n - h);
        }
        if best.map(|(d, _)| distance < d).unwrap_or(true) {
            best = Some((distance, near));
        }
    }
    best.map(|(_, q)| q)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The UR5 table (`cbd_protocol::ur5`) with every θ offset set, a tool off the flange axis and
    /// a rotated, shifted base: a UR-type chain the closed form must handle in general.
    fn ur5(theta_offset: f64) -> DhChain {
        let mut chain = cbd_protocol::ur5::chain();
        for joint in chain.joints.iter_mut() {
            joint.theta_offset = theta_offset;
        }
        chain.tool.translation = [5.0, -3.0, 31.0];
        chain.base = Transform { rotation: [0.0, -1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0], translation: [100.0, 20.0, -50.0] };
        chain
    }

    fn pose_distance(a: &Pose, b: &Pose) -> f64 {
        let mut worst: f64 = 0.0;
        for r in 0..3 {
            for c in 0..3 {
                worst = worst.max((a[r][c] - b[r][c]).abs() * 1000.0);
            }
            worst = worst.max((a[r][3] - b[r][3]).abs());
        }
        worst
    }

    #[test]
    fn all_eight_solutions_reproduce_the_pose_and_include_the_source() {
        for offset in [0.0, 0.3] {
            let chain = ur5(offset);
            assert!(is_ur_type(&chain));
            let mut s = 3u64;
            let mut next = || {
                s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                ((s >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
            };
            let (mut worst, mut counted) = (0.0f64, 0);
            for _ in 0..500 {
                let q: [f64; 6] = core::array::from_fn(|_| 3.0 * next());
                let pose = tool_pose(&chain, &q);
                let sols = solutions(&chain, &pose);
                let mut found = false;
                for sol in sols.iter().flatten() {
                    worst = worst.max(pose_distance(&tool_pose(&chain, sol), &pose));
                    counted += 1;
                    found |= sol.iter().zip(&q).all(|(a, b)| libm::cos(a - b) > 1.0 - 1e-10);
                }
                assert!(found, "{q:?} not among {sols:?}");
                let near = nearest_to_hint(&chain, &[pose[0][3], pose[1][3], pose[2][3]], &q).unwrap();
                assert!(near.iter().zip(&q).all(|(a, b)| (a - b).abs() < 1e-6), "{near:?} vs {q:?}");
            }
            // Lengths in mm: 1e-9 mm and 1e-12 in the rotation (scaled by 1000 above).
            assert!(worst < 1e-9, "worst FK round trip {worst}");
            assert!(counted > 500 * 6, "only {counted} solutions over 500 poses");
        }
    }

    #[test]
    fn unreachable_non_finite_and_other_chains_give_none() {
        let chain = ur5(0.0);
        let mut pose = tool_pose(&chain, &[0.1, -1.0, 1.0, 0.2, 0.3, 0.4]);
        pose[0][3] = 5000.0;
        assert!(solutions(&chain, &pose).iter().all(Option::is_none));
        pose[0][3] = f64::NAN;
        assert!(solutions(&chain, &pose).iter().all(Option::is_none));
        let mut other = ur5(0.0);
        other.joints[3].alpha = 0.2;
        assert!(!is_ur_type(&other));
        other = ur5(0.0);
        other.convention = DhConvention::Modified;
        assert!(!is_ur_type(&other));
    }
}

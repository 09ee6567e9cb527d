//! Closed-form inverse kinematics of the two-link planar arm y = l1 (cos q1, sin q1) + l2 (cos, sin)(q1 + q2).

/// Which of the two solutions: the sign of sin q2 (q2 ∈ [0, π] or [−π, 0]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Elbow {
    /// q2 ∈ [0, π].
    Positive,
    /// q2 ∈ [−π, 0].
    Negative,
}

/// The joint angles that put the tip of a two-link arm (links `l1`, `l2`) at `target`, for one
/// elbow (law of cosines):
///
/// ```text
/// cos q2 = (x² + y² − l1² − l2²) / (2 l1 l2),   q2 = ± acos(cos q2)
/// q1 = atan2(y, x) − atan2(l2 sin q2, l1 + l2 cos q2)
/// ```
///
/// `None` when the target lies outside the annulus |l1 − l2| ≤ |y| ≤ l1 + l2 (unreachable), for
/// non-positive or non-finite lengths, or a non-finite target.
pub fn two_link(l1: f64, l2: f64, target: [f64; 2], elbow: Elbow) -> Option<[f64; 2]> {
    let [x, y] = target;
    if !(l1 > 0.0 && l2 > 0.0 && l1.is_finite() && l2.is_finite() && x.is_finite() && y.is_finite()) {
        return None;
    }
    let cos_q2 = (x * x + y * y - l1 * l1 - l2 * l2) / (2.0 * l1 * l2);
    if !(-1.0..=1.0).contains(&cos_q2) {
        return None;
    }
    let sin_abs = libm::sqrt(1.0 - cos_q2 * cos_q2);
    let sin_q2 = match elbow {
        Elbow::Positive => sin_abs,
        Elbow::Negative => -sin_abs,
    };
    let q2 = libm::atan2(sin_q2, cos_q2);
    let q1 = libm::atan2(y, x) - libm::atan2(l2 * sin_q2, l1 + l2 * cos_q2);
    Some([q1, q2])
}

/// Both elbows' solutions ([`two_link`]), positive first.
pub fn two_link_both(l1: f64, l2: f64, target: [f64; 2]) -> Option<[[f64; 2]; 2]> {
    Some([two_link(l1, l2, target, Elbow::Positive)?, two_link(l1, l2, target, Elbow::Negative)?])
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tip(l1: f64, l2: f64, q: [f64; 2]) -> [f64; 2] {
        [l1 * libm::cos(q[0]) + l2 * libm::cos(q[0] + q[1]), l1 * libm::sin(q[0]) + l2 * libm::sin(q[0] + q[1])]
    }

    #[test]
    fn both_elbows_reproduce_the_target_through_forward_kinematics() {
        let (l1, l2) = (1.0, 0.5);
        let mut worst: f64 = 0.0;
        let mut s = 1u64;
        let mut next = || {
            s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (s >> 11) as f64 / (1u64 << 53) as f64
        };
        for _ in 0..2000 {
            // A target from random joints (reachable by construction), then both solutions.
            let q = [6.0 * next() - 3.0, 6.0 * next() - 3.0];
            let target = tip(l1, l2, q);
            let [pos, neg] = two_link_both(l1, l2, target).unwrap();
            assert!(pos[1] >= 0.0 && neg[1] <= 0.0);
            for sol in [pos, neg] {
                let y = tip(l1, l2, sol);
                worst = worst.max((y[0] - target[0]).hypot(y[1] - target[1]));
            }
            // One of the two is the configuration the target came from (angles modulo 2π).
            let same = |a: f64, b: f64| libm::cos(a - b) > 1.0 - 1e-12;
            assert!([pos, neg].iter().any(|c| same(c[0], q[0]) && same(c[1], q[1])), "{q:?} not among {pos:?} {neg:?}");
        }
        assert!(worst < 1e-14, "worst round-trip error {worst}");
    }

    #[test]
    fn outside_the_annulus_and_non_finite_input_give_none() {
        assert_eq!(two_link(1.0, 0.5, [1.6, 0.0], Elbow::Positive), None);
        assert_eq!(two_link(1.0, 0.5, [0.4, 0.0], Elbow::Negative), None);
        assert_eq!(two_link(1.0, 0.5, [f64::NAN, 0.0], Elbow::Positive), None);
        assert_eq!(two_link(1.0, 0.5, [f64::INFINITY, 0.0], Elbow::Positive), None);
        assert_eq!(two_link(0.0, 0.5, [0.5, 0.0], Elbow::Positive), None);
        // The boundary itself is reachable (fully stretched).
        let q = two_link(1.0, 0.5, [1.5, 0.0], Elbow::Positive).unwrap();
        assert!(q[0].abs() < 1e-15 && q[1].abs() < 1e-15);
    }
}

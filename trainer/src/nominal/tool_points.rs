//! Several measured points on the tool (docs/DESIGN.md §12): a point's chain, a measured pose read
//! as points, and the least-squares tool frame of a pose's points (for orientation errors).

use super::rigid_fit::{axis_angle, rigid_fit};
use super::Frame;
use cbd_protocol::{DhChain, NominalModel};

/// `chain` with its tool frame moved to the tool point `p` (offset in the tool frame): its tool
/// position is that point's, y_j = walk · tool · (p_j, 1) (the runtime's `at_tool_point`).
pub fn point_chain(chain: &DhChain, p: [f64; 3]) -> DhChain {
    let mut with_point = chain.clone();
    with_point.tool_points = heapless::Vec::from_slice(&[p]).expect("one point");
    match cbd_runtime::internals::kinematics::tool_point::at_tool_point(&NominalModel::DhChain(with_point), 0) {
        Some(NominalModel::DhChain(moved)) => moved,
        _ => unreachable!("a DH chain with one tool point"),
    }
}

/// The rules every list of tool points obeys, wherever it comes from (a model file's
/// `[chain.tool] points`, `cbd simulate --tool-points`): 1 to `MAX_TOOL_POINTS`, each coordinate
/// finite and within the blob's [`cbd_protocol::MAX_TOOL_POINT_COORDINATE`], no two the same.
/// The message says which point and why (the caller names the field or flag).
pub fn check_tool_points(points: &[[f64; 3]]) -> Result<(), String> {
    use cbd_protocol::{MAX_TOOL_POINTS, MAX_TOOL_POINT_COORDINATE};
    if points.is_empty() || points.len() > MAX_TOOL_POINTS {
        return Err(format!("{} points; 1 to {MAX_TOOL_POINTS} are supported", points.len()));
    }
    for (j, p) in points.iter().enumerate() {
        if let Some(v) = p.iter().find(|v| !(v.abs() <= MAX_TOOL_POINT_COORDINATE)) {
            return Err(format!(
                "point {}: {} is not a finite offset within ±{MAX_TOOL_POINT_COORDINATE:e} (a lever on the tool, in the length unit)",
                j + 1,
                crate::error::number(*v)
            ));
        }
        if let Some(k) = points[..j].iter().position(|o| o == p) {
            return Err(format!("points {} and {} are the same point", k + 1, j + 1));
        }
    }
    Ok(())
}

/// The unit quaternion (w, x, y, z), w ≥ 0, of a rotation matrix (Shepperd's method: the largest
/// of 1 + tr, 1 + 2 r_ii − tr taken as the pivot).
pub fn quaternion_of(r: &[[f64; 3]; 3]) -> [f64; 4] {
    let t = r[0][0] + r[1][1] + r[2][2];
    let q = if t >= r[0][0].max(r[1][1]).max(r[2][2]) {
        let s = 2.0 * (1.0 + t).sqrt();
        [s / 4.0, (r[2][1] - r[1][2]) / s, (r[0][2] - r[2][0]) / s, (r[1][0] - r[0][1]) / s]
    } else if r[0][0] >= r[1][1] && r[0][0] >= r[2][2] {
        let s = 2.0 * (1.0 + 2.0 * r[0][0] - t).sqrt();
        [(r[2][1] - r[1][2]) / s, s / 4.0, (r[0][1] + r[1][0]) / s, (r[0][2] + r[2][0]) / s]
    } else if r[1][1] >= r[2][2] {
        let s = 2.0 * (1.0 + 2.0 * r[1][1] - t).sqrt();
        [(r[0][2] - r[2][0]) / s, (r[0][1] + r[1][0]) / s, s / 4.0, (r[1][2] + r[2][1]) / s]
    } else {
        let s = 2.0 * (1.0 + 2.0 * r[2][2] - t).sqrt();
        [(r[1][0] - r[0][1]) / s, (r[0][2] + r[2][0]) / s, (r[1][2] + r[2][1]) / s, s / 4.0]
    };
    let sign = if q[0] < 0.0 { -1.0 } else { 1.0 };
    let norm = q.iter().map(|v| v * v).sum::<f64>().sqrt();
    q.map(|v| sign * v / norm)
}

/// R(q) of a unit quaternion q = (w, x, y, z).
pub fn rotation_of_quaternion([w, x, y, z]: [f64; 4]) -> [[f64; 3]; 3] {
    [
        [1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y - w * z), 2.0 * (x * z + w * y)],
        [2.0 * (x * y + w * z), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z - w * x)],
        [2.0 * (x * z - w * y), 2.0 * (y * z + w * x), 1.0 - 2.0 * (x * x + y * y)],
    ]
}

/// Tool point `p` of a measured pose (position `origin`, rotation `r`): y = origin + R p.
pub fn point_of_pose(origin: &[f64], r: &[[f64; 3]; 3], p: &[f64; 3]) -> [f64; 3] {
    std::array::from_fn(|a| origin[a] + (r[a][0] * p[0] + r[a][1] * p[1] + r[a][2] * p[2]))
}

/// The least-squares tool frame of one pose's measured `points` (in the task frame), the rigid
/// motion carrying the tool points onto them (Kabsch/Horn, `rigid_fit::rigid_fit`); `None` for
/// fewer than 3 points or points on a line.
pub fn tool_frame(tool_points: &[[f64; 3]], points: &[[f64; 3]]) -> Option<Frame> {
    rigid_fit(tool_points, points)
}

/// The angle (radians) of the rotation between two frames' orientations, |log(R_aᵀ R_b)|.
pub fn rotation_angle(a: &Frame, b: &Frame) -> f64 {
    axis_angle(&a.inverse().compose(b)).1.abs()
}

#[cfg(test)]
mod tests {
    use super::*;

    // Angles near π on purpose (3.14: the quaternion's small-w branch), not π.
    #[allow(clippy::approx_constant)]
    #[test]
    fn quaternions_round_trip_every_branch_and_frames_fit_exact_points() {
        for (axis, angle) in [([0.0, 0.0, 1.0], 0.3), ([1.0, 0.0, 0.0], 3.0), ([0.0, 1.0, 0.0], 3.1), ([0.0, 0.6, 0.8], 3.14)] {
            let f = super::super::rotation_about(axis, angle);
            let r = rotation_of_quaternion(quaternion_of(&f.rotation()));
            for a in 0..3 {
                for b in 0..3 {
                    assert!((r[a][b] - f.rotation()[a][b]).abs() < 1e-14, "{axis:?} {angle}");
                }
            }
        }
        let pose = super::super::rotation_about([0.6, 0.0, 0.8], 0.7).with_translation([1.0, -2.0, 3.0]);
        let tool = [[0.0, 0.0, 0.0], [100.0, 0.0, 0.0], [50.0, 86.6, 0.0]];
        let measured: Vec<[f64; 3]> = tool.iter().map(|p| pose.apply(*p)).collect();
        let fitted = tool_frame(&tool, &measured).unwrap();
        assert!(rotation_angle(&fitted, &pose) < 1e-12);
        assert!(super::super::norm(super::super::sub(fitted.translation(), pose.translation())) < 1e-11);
    }
}

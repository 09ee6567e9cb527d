//! Nominal models built from files: rigid transforms (the runtime's [`Frame`]) as URDF and model
//! files give them, and the conversion of a URDF joint
//! chain into an equivalent standard Denavit–Hartenberg chain. The DH frame walk itself is the
//! runtime's (`cbd_runtime::internals::kinematics::rigid::dh_walk`): one walk for the trainer and the controller.

pub mod dh_parameters;
pub mod export;
pub mod planar;
mod positions;
pub use positions::{positions, row_kinematics};
pub mod rigid_fit;
pub mod tool_points;
pub mod urdf;

pub use cbd_runtime::internals::kinematics::spatial::Frame;
pub(crate) use cbd_runtime::internals::kinematics::spatial::{add, cross, dot, norm, scale, sub};

/// Rotation by `angle` (radians) about the unit vector `axis` (Rodrigues), no translation.
pub fn rotation_about(axis: [f64; 3], angle: f64) -> Frame {
    let (s, c) = angle.sin_cos();
    let [x, y, z] = axis;
    let v = 1.0 - c;
    Frame::new(
        [
            [c + x * x * v, x * y * v - z * s, x * z * v + y * s],
            [y * x * v + z * s, c + y * y * v, y * z * v - x * s],
            [z * x * v - y * s, z * y * v + x * s, c + z * z * v],
        ],
        [0.0; 3],
    )
}

/// URDF / ROS convention (radians): R = Rz(yaw) Ry(pitch) Rx(roll) (fixed axes x, then y, then z), no translation.
pub fn rpy(roll: f64, pitch: f64, yaw: f64) -> Frame {
    let rx = rotation_about([1.0, 0.0, 0.0], roll);
    let ry = rotation_about([0.0, 1.0, 0.0], pitch);
    let rz = rotation_about([0.0, 0.0, 1.0], yaw);
    rz.compose(&ry).compose(&rx)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rpy_and_inverse_are_consistent() {
        let p = rpy(0.3, -0.7, 1.9).with_translation([1.0, -2.0, 0.5]);
        let id = p.compose(&p.inverse());
        for i in 0..3 {
            assert!(id.translation()[i].abs() < 1e-14);
            for j in 0..3 {
                assert!((id.rotation()[i][j] - if i == j { 1.0 } else { 0.0 }).abs() < 1e-14);
            }
        }
        // Pure yaw turns x into y.
        let y = rpy(0.0, 0.0, std::f64::consts::FRAC_PI_2).rotate([1.0, 0.0, 0.0]);
        assert!((y[0]).abs() < 1e-15 && (y[1] - 1.0).abs() < 1e-15);
    }
}

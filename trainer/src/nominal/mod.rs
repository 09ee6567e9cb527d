//! Nominal models built from files: rigid-transform helpers, and the conversion of a URDF joint
//! chain into an equivalent standard Denavit–Hartenberg chain. The DH frame walk itself is the
//! runtime's (`cbd_runtime::kinematics::rigid::dh_walk`): one walk for the trainer and the controller.

pub mod dh_parameters;
pub mod planar;
mod positions;
pub use positions::positions;
pub mod register;
pub mod urdf;

use cbd_protocol::Transform;

/// A rigid transform as rotation (3×3, `r[row][col]`) and translation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pose {
    pub r: [[f64; 3]; 3],
    pub t: [f64; 3],
}

impl Pose {
    pub const IDENTITY: Pose = Pose { r: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]], t: [0.0; 3] };

    pub fn from_transform(t: &Transform) -> Pose {
        let m = &t.rotation;
        Pose { r: [[m[0], m[1], m[2]], [m[3], m[4], m[5]], [m[6], m[7], m[8]]], t: t.translation }
    }

    pub fn to_transform(&self) -> Transform {
        let r = &self.r;
        Transform { rotation: [r[0][0], r[0][1], r[0][2], r[1][0], r[1][1], r[1][2], r[2][0], r[2][1], r[2][2]], translation: self.t }
    }

    /// `self ∘ other`: first `other`, then `self`.
    pub fn compose(&self, other: &Pose) -> Pose {
        let mut out = Pose { r: [[0.0; 3]; 3], t: self.t };
        for i in 0..3 {
            for j in 0..3 {
                out.r[i][j] = (0..3).map(|k| self.r[i][k] * other.r[k][j]).sum();
            }
            out.t[i] += (0..3).map(|k| self.r[i][k] * other.t[k]).sum::<f64>();
        }
        out
    }

    pub fn inverse(&self) -> Pose {
        let mut out = Pose { r: [[0.0; 3]; 3], t: [0.0; 3] };
        for i in 0..3 {
            for j in 0..3 {
                out.r[i][j] = self.r[j][i];
            }
        }
        for i in 0..3 {
            out.t[i] = -(0..3).map(|k| out.r[i][k] * self.t[k]).sum::<f64>();
        }
        out
    }

    /// R v (a direction).
    pub fn rotate(&self, v: [f64; 3]) -> [f64; 3] {
        let mut out = [0.0; 3];
        for (i, o) in out.iter_mut().enumerate() {
            *o = (0..3).map(|k| self.r[i][k] * v[k]).sum();
        }
        out
    }

    /// R p + t (a point).
    pub fn apply(&self, p: [f64; 3]) -> [f64; 3] {
        let mut out = self.rotate(p);
        for (o, t) in out.iter_mut().zip(self.t) {
            *o += t;
        }
        out
    }

    /// The axis of column `c` of the rotation (the frame's x, y or z direction).
    pub fn axis(&self, c: usize) -> [f64; 3] {
        [self.r[0][c], self.r[1][c], self.r[2][c]]
    }

    pub fn translation(t: [f64; 3]) -> Pose {
        Pose { t, ..Pose::IDENTITY }
    }

    /// Rotation by `angle` about the unit vector `axis` (Rodrigues).
    pub fn axis_angle(axis: [f64; 3], angle: f64) -> Pose {
        let (s, c) = angle.sin_cos();
        let [x, y, z] = axis;
        let v = 1.0 - c;
        Pose {
            r: [
                [c + x * x * v, x * y * v - z * s, x * z * v + y * s],
                [y * x * v + z * s, c + y * y * v, y * z * v - x * s],
                [z * x * v - y * s, z * y * v + x * s, c + z * z * v],
            ],
            t: [0.0; 3],
        }
    }

    /// URDF / ROS convention: R = Rz(yaw) Ry(pitch) Rx(roll) (fixed axes x, then y, then z).
    pub fn rpy(roll: f64, pitch: f64, yaw: f64) -> Pose {
        let rx = Pose::axis_angle([1.0, 0.0, 0.0], roll);
        let ry = Pose::axis_angle([0.0, 1.0, 0.0], pitch);
        let rz = Pose::axis_angle([0.0, 0.0, 1.0], yaw);
        rz.compose(&ry).compose(&rx)
    }
}

pub(crate) fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

pub(crate) fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}

pub(crate) fn norm(a: [f64; 3]) -> f64 {
    dot(a, a).sqrt()
}

pub(crate) fn scale(a: [f64; 3], s: f64) -> [f64; 3] {
    [a[0] * s, a[1] * s, a[2] * s]
}

pub(crate) fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

pub(crate) fn add(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rpy_and_inverse_are_consistent() {
        let p = Pose { t: [1.0, -2.0, 0.5], ..Pose::rpy(0.3, -0.7, 1.9) };
        let id = p.compose(&p.inverse());
        for i in 0..3 {
            assert!(id.t[i].abs() < 1e-14);
            for j in 0..3 {
                assert!((id.r[i][j] - if i == j { 1.0 } else { 0.0 }).abs() < 1e-14);
            }
        }
        // Pure yaw turns x into y.
        let y = Pose::rpy(0.0, 0.0, std::f64::consts::FRAC_PI_2).rotate([1.0, 0.0, 0.0]);
        assert!((y[0]).abs() < 1e-15 && (y[1] - 1.0).abs() < 1e-15);
    }
}

//! The paper's planar RR benchmark (its §4; docs/DESIGN.md §6): nominal l1 = 1, l2 = 0.5, and a simulated
//! "real" arm with link-length errors, a base offset and static gravity effects on the links.

use crate::data::Measurements;
use cbd_protocol::NominalModel;

/// The nominal model of the paper: l1 = 1, l2 = 0.5 (`cbd_protocol::paper_rr::LENGTHS`).
pub fn nominal() -> NominalModel {
    NominalModel::planar(&cbd_protocol::paper_rr::LENGTHS).expect("two links fit")
}

/// A planar arm as a DH chain (`nominal::planar::as_dh`) with link `lengths`, its base moved by
/// (x, y) and turned by `base_yaw` (rad) in the plane, and joint offsets `offsets` (rad): the
/// rigid geometry of a real planar arm, which a `PlanarChain` (link lengths only) cannot hold.
/// Gravity along −y, unit masses.
pub fn planar_arm(lengths: &[f64], base: [f64; 2], base_yaw: f64, offsets: &[f64]) -> NominalModel {
    let mut model = crate::nominal::planar::as_dh(&NominalModel::planar(lengths).expect("at most MAX_JOINTS links"));
    if let NominalModel::DhChain(c) = &mut model {
        let pose = crate::nominal::rotation_about([0.0, 0.0, 1.0], base_yaw).with_translation([base[0], base[1], 0.0]);
        c.base = pose.to_transform();
        for (j, o) in c.joints.iter_mut().zip(offsets) {
            j.theta_offset = *o;
        }
    }
    model
}

/// The simulated real arm. Gravity acts along −y.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RealRr {
    /// True link lengths (nominal 1 and 0.5).
    pub lengths: [f64; 2],
    pub base_offset: [f64; 2],
    /// Tip deflection per unit transverse gravity load of each link (bending, cantilever).
    pub bending: [f64; 2],
    /// Elongation per unit axial gravity load (stretching when hanging, shrinking when upright).
    pub stretch: [f64; 2],
}

impl Default for RealRr {
    fn default() -> Self {
        RealRr { lengths: [1.09, 0.46], base_offset: [0.03, -0.02], bending: [0.03, 0.015], stretch: [0.02, 0.01] }
    }
}

impl RealRr {
    /// Position of the real arm's tip at joint angles `x`.
    pub fn position(&self, x: &[f64]) -> [f64; 2] {
        let mut p = self.base_offset;
        let mut theta = 0.0;
        let mut slope = 0.0; // rotation the bent previous link imposes on the next one
        for k in 0..2 {
            theta += x[k];
            let th = theta + slope;
            let (e, nrm) = ([th.cos(), th.sin()], [-th.sin(), th.cos()]);
            let g = [0.0, -1.0];
            let transverse = g[0] * nrm[0] + g[1] * nrm[1];
            let axial = g[0] * e[0] + g[1] * e[1];
            let length = self.lengths[k] + self.stretch[k] * axial;
            let deflection = self.bending[k] * transverse;
            for c in 0..2 {
                p[c] += length * e[c] + deflection * nrm[c];
            }
            // A uniformly loaded cantilever's tip slope is 4/3 of deflection / length.
            slope += 4.0 / 3.0 * deflection / self.lengths[k];
        }
        p
    }

    /// Measurements of the real arm at `joints` (row-major pairs).
    pub fn measure(&self, joints: &[f64]) -> Measurements {
        let mut out = Measurements::new(2, 2);
        for x in joints.chunks_exact(2) {
            out.push(x, &self.position(x));
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::simulate::{configurations, Sampling};

    #[test]
    fn real_arm_errors_are_in_the_papers_range() {
        let nominal = nominal();
        let real = RealRr::default();
        let x = configurations(Sampling::Uniform { count: 2000, seed: 1 }, 2);
        let mut errors = Vec::new();
        for q in x.chunks_exact(2) {
            let k0 = cbd_runtime::internals::kinematics::forward_kinematics(&nominal, q);
            let y = real.position(q);
            errors.push(((k0.position[0] - y[0]).powi(2) + (k0.position[1] - y[1]).powi(2)).sqrt());
        }
        let mean = errors.iter().sum::<f64>() / errors.len() as f64;
        assert!((0.07..0.16).contains(&mean), "mean nominal error {mean}");
    }
}

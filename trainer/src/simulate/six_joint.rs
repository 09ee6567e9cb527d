//! A simulated 6-joint arm: UR5-like nominal DH model (mm), and a "real" robot with
//! (a) geometric errors in every DH parameter, the base and the tool, and (b) gravity-dependent
//! joint compliance: each joint deflects by c_i τ_i(q), τ_i the gravity torque about its axis from
//! point masses at the link centres, and (c) Gaussian measurement noise. Deterministic for a seed.

use super::add_noise;
use crate::data::Measurements;
use crate::nominal::{cross, dot, sub};
use cbd_protocol::{DhChain, NominalModel};
use cbd_runtime::internals::kinematics::forward_kinematics;
use cbd_runtime::internals::kinematics::rigid::dh_walk;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Standard gravity, N/kg, along −z of the base frame.
pub const GRAVITY: f64 = 9.81;

#[derive(Debug, Clone, PartialEq)]
pub struct SixJointRobot {
    /// What the controller believes (UR5 DH table, mm, tool 31 mm along flange z).
    pub nominal: NominalModel,
    /// The real geometry.
    pub real: DhChain,
    /// Mass of each link (kg), at the midpoint of the origins of DH frames k and k+1 (link k
    /// moves with joint k).
    pub link_masses: [f64; 6],
    /// Joint compliance, rad per N·mm of gravity torque.
    pub compliance: [f64; 6],
    /// Standard deviation of the measurement noise per coordinate (mm).
    pub noise_std: f64,
}

/// The UR5 nominal model used by the simulation (standard DH, mm).
pub use cbd_protocol::ur5::chain as ur5_nominal;

impl SixJointRobot {
    /// UR5-like robot with geometric errors drawn from `seed`: lengths ±0.5 mm, angles ±0.1°
    /// per DH parameter, base ±1 mm / ±0.05°, tool ±0.5 mm and turned ±0.1° about each of its
    /// axes (a mounting error: it moves tool points off the tool origin only, so single-point data
    /// are as before it was added); UR5 link masses; compliance giving gravity deflections of order
    /// 0.1 mm at the tool; noise 0.01 mm.
    pub fn ur5_like(seed: u64) -> SixJointRobot {
        let nominal = ur5_nominal();
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let deg = std::f64::consts::PI / 180.0;
        let mut real = nominal.clone();
        for j in real.joints.iter_mut() {
            j.a += rng.gen_range(-0.5..0.5);
            j.d += rng.gen_range(-0.5..0.5);
            j.alpha += rng.gen_range(-0.1..0.1) * deg;
            j.theta_offset += rng.gen_range(-0.1..0.1) * deg;
        }
        let mut p = vec![0.0; crate::nominal::dh_parameters::parameter_count(6)];
        let o = 24;
        for k in 0..3 {
            p[o + k] = rng.gen_range(-1.0..1.0);
            p[o + 3 + k] = rng.gen_range(-0.05..0.05) * deg;
            p[o + 6 + k] = rng.gen_range(-0.5..0.5);
        }
        // Drawn last, so every other draw is what it was before tool points existed.
        p.extend((0..3).map(|_| rng.gen_range(-0.1..0.1) * deg));
        let real = crate::nominal::dh_parameters::apply_parameters(&real, &p);
        SixJointRobot {
            nominal: NominalModel::DhChain(nominal),
            real,
            link_masses: [3.7, 8.393, 2.275, 1.219, 1.219, 0.1879],
            compliance: [1e-9, 4e-9, 4e-9, 6e-9, 6e-9, 6e-9],
            noise_std: 0.01,
        }
    }

    /// Gravity torque about each joint axis of the real arm at `q` (N·mm).
    pub fn gravity_torques(&self, q: &[f64]) -> [f64; 6] {
        let walk = dh_walk(&self.real, q);
        // Link k (0-based) moves with joint k and spans the origins of frames k and k+1
        // (o_k − o_{k−1} = d z + a x depends on θ_k in standard DH).
        let centres: Vec<[f64; 3]> = (0..6)
            .map(|k| {
                let (a, b) = (if k == 0 { walk.start } else { walk.ends[k - 1] }, walk.ends[k]);
                [(a[0] + b[0]) / 2.0, (a[1] + b[1]) / 2.0, (a[2] + b[2]) / 2.0]
            })
            .collect();
        let mut tau = [0.0; 6];
        for i in 0..6 {
            for k in i..6 {
                let force = [0.0, 0.0, -GRAVITY * self.link_masses[k]];
                tau[i] += dot(cross(sub(centres[k], walk.origins[i]), force), walk.axes[i]);
            }
        }
        tau
    }

    /// Joint angles the real arm actually has when commanded `q`: q + c ∘ τ(q).
    pub fn deflected(&self, q: &[f64]) -> [f64; 6] {
        let tau = self.gravity_torques(q);
        let mut out = [0.0; 6];
        for i in 0..6 {
            out[i] = q[i] + self.compliance[i] * tau[i];
        }
        out
    }

    /// Noise-free position of the real arm when commanded `q` (mm).
    pub fn true_position(&self, q: &[f64]) -> [f64; 3] {
        let real = NominalModel::DhChain(self.real.clone());
        forward_kinematics(&real, &self.deflected(q)).position
    }

    /// Measurements at `joints` (row-major, 6 per row): commanded angles and measured positions
    /// (true position plus noise drawn from `noise_seed`).
    pub fn measure(&self, joints: &[f64], noise_seed: u64) -> Measurements {
        let mut positions: Vec<f64> = joints.chunks_exact(6).flat_map(|q| self.true_position(q)).collect();
        add_noise(&mut positions, self.noise_std, noise_seed);
        Measurements {
            n_joints: 6,
            task_dim: 3,
            points_per_pose: 1,
            joints: joints.to_vec(),
            positions,
            order: crate::data::RowOrder::Measured,
        }
    }
}

/// `count` random configurations (radians, row-major) in a UR5-like working range:
/// q1, q4, q5, q6 ∈ [−π, π], q2 ∈ [−π, 0] (upper arm above the base), q3 ∈ [−2.8, 2.8].
pub fn random_configurations(count: usize, seed: u64) -> Vec<f64> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    (0..count).flat_map(|_| WORKING_RANGE.map(|(lo, hi)| rng.gen_range(lo..hi))).collect()
}

/// The working range [`random_configurations`] samples (radians).
pub const WORKING_RANGE: [(f64, f64); 6] = {
    use std::f64::consts::PI;
    [(-PI, PI), (-PI, 0.0), (-2.8, 2.8), (-PI, PI), (-PI, PI), (-PI, PI)]
};

/// `count` configurations along a random walk in the same working range (`super::random_walk`:
/// Gaussian steps of standard deviation `step` radians per joint, reflected at the range's ends).
pub fn walk_configurations(count: usize, step: f64, seed: u64) -> Vec<f64> {
    super::random_walk(count, step, &WORKING_RANGE, seed)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::report::stats::ErrorStats;

    #[test]
    fn deterministic_and_sized_like_a_real_arm() {
        let robot = SixJointRobot::ur5_like(42);
        assert_eq!(robot, SixJointRobot::ur5_like(42));
        let q = random_configurations(200, 1);
        assert_eq!(q, random_configurations(200, 1));
        let a = robot.measure(&q, 9);
        assert_eq!(a, robot.measure(&q, 9));
        assert_eq!((a.len(), a.n_joints, a.task_dim), (200, 6, 3));
        // Nominal error: millimetres, like the real UR5 (2.6 mm).
        let nominal: Vec<f64> = (0..a.len()).flat_map(|i| forward_kinematics(&robot.nominal, a.joints(i)).position).collect();
        let e = ErrorStats::of_positions(&nominal, &a.positions, 3);
        assert!(e.mean > 0.5 && e.mean < 10.0, "{e:?}");
        // Compliance alone moves the tool by about 0.01–1 mm.
        let real = NominalModel::DhChain(robot.real.clone());
        let rigid: Vec<f64> = q.chunks_exact(6).flat_map(|c| forward_kinematics(&real, c).position).collect();
        let flex: Vec<f64> = q.chunks_exact(6).flat_map(|c| robot.true_position(c)).collect();
        let e = ErrorStats::of_positions(&rigid, &flex, 3);
        assert!(e.mean > 0.01 && e.max < 1.0, "{e:?}");
        // Noise has the stated size.
        let truth: Vec<f64> = q.chunks_exact(6).flat_map(|c| robot.true_position(c)).collect();
        let rms = (truth.iter().zip(&a.positions).map(|(t, m)| (t - m).powi(2)).sum::<f64>() / truth.len() as f64).sqrt();
        assert!((rms - robot.noise_std).abs() < 0.2 * robot.noise_std, "noise rms {rms}");
    }

    #[test]
    fn gravity_torque_matches_a_hand_computation() {
        // Upper arm horizontal (q2 = 0 in the UR5 table: links 2 and 3 along the base x axis).
        let mut robot = SixJointRobot::ur5_like(1);
        robot.real = ur5_nominal();
        robot.link_masses = [0.0, 1.0, 2.0, 0.0, 0.0, 0.0];
        let tau = robot.gravity_torques(&[0.0, 0.0, 0.0, 0.0, 0.0, 0.0]);
        // Upper arm (1 kg) centred 212.5 mm from the shoulder axis, forearm (2 kg) centred
        // 425 + 196.125 mm from it and 196.125 mm from the elbow axis.
        assert!((tau[0]).abs() < 1e-9, "joint 1 axis is vertical: {tau:?}");
        let shoulder: f64 = GRAVITY * (212.5 + 2.0 * (425.0 + 196.125));
        assert!((tau[1].abs() - shoulder).abs() < 1e-6, "{tau:?}");
        assert!((tau[2].abs() - GRAVITY * 2.0 * 196.125).abs() < 1e-6, "{tau:?}");
        assert!(tau[3..].iter().all(|t| t.abs() < 1e-9), "{tau:?}");
    }

    #[test]
    fn dh_calibration_leaves_only_the_compliance_and_noise() {
        use crate::parametric::{calibrate_dh, DhCalibrationOptions};
        let robot = SixJointRobot::ur5_like(3);
        let train = robot.measure(&random_configurations(300, 4), 5);
        let test_q = random_configurations(300, 6);
        let fit = calibrate_dh(&robot.nominal, &train, &DhCalibrationOptions::default()).unwrap();
        let pred: Vec<f64> = test_q.chunks_exact(6).flat_map(|q| forward_kinematics(&fit.model, q).position).collect();
        let truth: Vec<f64> = test_q.chunks_exact(6).flat_map(|q| robot.true_position(q)).collect();
        let e = ErrorStats::of_positions(&pred, &truth, 3);
        // Geometric errors are removed; gravity compliance (not a DH effect) remains.
        assert!(e.mean < 0.2 && e.mean > 0.005, "{e:?}");
    }
}

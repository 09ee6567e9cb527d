//! The planner against its promises: limits and singular configurations, and its predicted error
//! against the error a calibration on the planned poses actually reaches.

use super::*;
use crate::calibrate::Geometry;
use crate::simulate::six_joint::{random_configurations, SixJointRobot};

fn ur5_limits() -> (NominalModel, Vec<[f64; 2]>) {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../examples/ur5/simulated-six.toml");
    let file = crate::data::model_file::load_model_file(path).unwrap();
    let limits = file.column_spec().unwrap().joint_limits;
    (file.nominal, limits)
}

/// Every planned pose lies within the joint limits and at least 1° (linearised, joint space) from
/// a singular configuration, recomputed here; the pool did hold poses the filter had to leave out.
#[test]
fn planned_poses_respect_limits_and_singular_margin() {
    let rr = crate::simulate::rr::nominal();
    let rr_limits = [[-std::f64::consts::PI, std::f64::consts::PI], [-0.3, 0.3]];
    let (six, six_limits) = ur5_limits();
    for (nominal, limits, noise) in [(&rr, rr_limits.to_vec(), 1e-4), (&six, six_limits, 0.02)] {
        let sample = candidates::uniform_within(&limits, 300, 7);
        let reach = candidates::reach(nominal, &sample);
        let h = prior::stated(nominal, &sample, reach, prior::StatedPrior { error: 3e-4 * reach, noise });
        // The user's candidates include exactly singular poses (q2 = 0 for RR; q3 = q5 = 0 for the UR5).
        let singular: Vec<f64> = if nominal.n_joints() == 2 { vec![0.4, 0.0, 1.0, 0.01] } else { vec![0.1, -1.0, 0.0, 0.2, 0.0, 0.3] };
        let input = PlanInput {
            nominal,
            limits: &limits,
            to_model: None,
            user_candidates: &singular,
            measured: None,
            hyperparameters: h,
            geometry: Geometry::Calibrated,
        };
        let greedy = PlanOptions { count: 25, candidates: 1500, seed: 3, workspace: 32, evaluation: 100, ..PlanOptions::default() };
        // The exchange passes only choose among the same candidates.
        let maximin = PlanOptions { criterion: Criterion::Maximin, ..greedy.clone() };
        for options in [greedy.clone(), PlanOptions { exchange: 2, exchange_workspace: 48, ..greedy }, maximin] {
            let plan = plan(&input, &options).unwrap();
            assert_eq!(plan.poses.len(), 25);
            assert!(plan.rejected_singular >= 1, "the singular user candidates were left out");
            for pose in &plan.poses {
                assert!(candidates::within_limits(&pose.joints, &limits), "{:?} beyond {limits:?}", pose.joints);
                let d = candidates::singular_distance(nominal, &pose.joints, plan.reach);
                assert!(d >= candidates::SINGULAR_MARGIN, "{:?}: {d} rad from singular", pose.joints);
            }
            // The RR band |q2| ≤ 0.3 is mostly near the singular q2 = 0: nothing within 1° of it is chosen.
            if nominal.n_joints() == 2 {
                assert!(plan.poses.iter().all(|p| p.joints[1].abs() > 0.9 * candidates::SINGULAR_MARGIN));
            }
        }
    }
}

/// The same seed gives the same poses, with exchange passes on either workspace; the exchange
/// changes the greedy batch here, and its learning curve is recomputed for the new poses.
#[test]
fn exchanged_plans_are_deterministic() {
    let rr = crate::simulate::rr::nominal();
    let limits = [[0.0, 2.0 * std::f64::consts::PI]; 2];
    let sample = candidates::uniform_within(&limits, 300, 7);
    let reach = candidates::reach(&rr, &sample);
    let h = prior::stated(&rr, &sample, reach, prior::StatedPrior { error: 3e-4 * reach, noise: 1e-4 });
    let input = PlanInput {
        nominal: &rr,
        limits: &limits,
        to_model: None,
        user_candidates: &[],
        measured: None,
        hyperparameters: h,
        geometry: Geometry::Calibrated,
    };
    let greedy = PlanOptions { count: 16, candidates: 800, seed: 9, workspace: 48, evaluation: 200, ..PlanOptions::default() };
    let plain = plan(&input, &greedy).unwrap();
    for exchange_workspace in [0, 96] {
        let options = PlanOptions { exchange: 3, exchange_workspace, ..greedy.clone() };
        let (a, b) = (plan(&input, &options).unwrap(), plan(&input, &options).unwrap());
        assert_eq!(a.poses, b.poses, "exchange workspace {exchange_workspace}");
        assert!(a.exchange_swaps > 0 && a.poses != plain.poses, "exchange workspace {exchange_workspace}: no swap");
        // The learning curve falls pose by pose once the group is identified.
        let curve: Vec<f64> = a.poses.iter().filter_map(|p| p.predicted_rms).collect();
        assert!(curve.len() >= 12 && curve.windows(2).all(|w| w[1] <= w[0] * (1.0 + 1e-9)), "{curve:?}");
    }
}

/// A bad input is an error, not a panic.
#[test]
fn unbounded_joint_is_refused() {
    let rr = crate::simulate::rr::nominal();
    let limits = [[-1.0, 1.0], [f64::NEG_INFINITY, f64::INFINITY]];
    let h = prior::stated(&rr, &[0.0, 0.5], 1.5, prior::StatedPrior { error: 1e-3, noise: 1e-5 });
    let input = PlanInput {
        nominal: &rr,
        limits: &limits,
        to_model: None,
        user_candidates: &[],
        measured: None,
        hyperparameters: h,
        geometry: Geometry::Calibrated,
    };
    assert_eq!(plan(&input, &PlanOptions::default()).unwrap_err(), PlanError::UnboundedJoint { joint: 2 });
}

/// Poses the DH fit reproduces exactly (one pose measured 50 times) leave a residual of rounding
/// size: the evidence's noise box must not invert (it panicked in `f64::clamp`).
#[test]
fn exactly_fitted_data_give_hyperparameters_not_a_panic() {
    let rr = crate::simulate::rr::nominal();
    let data = Measurements {
        n_joints: 2,
        task_dim: 2,
        joints: [0.1, 0.2].repeat(50),
        positions: [1.3, 0.4].repeat(50),
        points_per_pose: 1,
        order: crate::data::RowOrder::Measured,
    };
    let (h, _) = prior::from_measurements(&rr, &data).expect("hyperparameters");
    assert!(h.sigma.is_finite() && h.sigma >= 0.0, "{h:?}");
}

/// A model with several tool points is refused (each pose would measure every point; the process
/// tracks one), whether the model or the measured data carry them.
#[test]
fn several_tool_points_are_refused() {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../examples/tool-points/six-points.toml");
    let file = crate::data::model_file::load_model_file(path).unwrap();
    let (_, limits) = ur5_limits();
    let h = prior::stated(&file.nominal, &[0.0; 6], 1000.0, prior::StatedPrior { error: 0.3, noise: 0.02 });
    let input = PlanInput {
        nominal: &file.nominal,
        limits: &limits,
        to_model: None,
        user_candidates: &[],
        measured: None,
        hyperparameters: h.clone(),
        geometry: Geometry::Calibrated,
    };
    assert_eq!(plan(&input, &PlanOptions::default()).unwrap_err(), PlanError::ToolPoints { points: 3 });
    let (six, _) = ur5_limits();
    let data = Measurements {
        n_joints: 6,
        task_dim: 3,
        joints: vec![0.1; 12],
        positions: vec![0.0; 18],
        points_per_pose: 3,
        order: crate::data::RowOrder::Measured,
    };
    let input = PlanInput {
        nominal: &six,
        limits: &limits,
        to_model: None,
        user_candidates: &[],
        measured: Some(&data),
        hyperparameters: h,
        geometry: Geometry::Calibrated,
    };
    assert_eq!(plan(&input, &PlanOptions::default()).unwrap_err(), PlanError::ToolPoints { points: 3 });
}

/// The six-joint arm (geometric errors, gravity compliance, 0.02 mm noise): 30 random poses measured,
/// 30 more planned from them; dh+cbd (Euler × 1: the posterior mean itself) fitted on all 60; its RMS
/// error against the true positions at 400 fresh random configurations within a factor 1.5 of the
/// predicted RMS error after the 60.
#[test]
fn predicted_error_matches_the_error_reached() {
    let (six, limits) = ur5_limits();
    let mut robot = SixJointRobot::ur5_like(1);
    robot.noise_std = 0.02;
    let first = robot.measure(&random_configurations(30, 11), 12);
    let (h, choice) = prior::from_measurements(&six, &first).unwrap();
    // On 30 poses of an arm with geometric errors the evidence calibrates its geometry.
    assert_eq!(choice.chosen, Geometry::Calibrated, "{}", choice.describe());
    let input = PlanInput {
        nominal: &six,
        limits: &limits,
        to_model: None,
        user_candidates: &[],
        measured: Some(&first),
        hyperparameters: h,
        geometry: choice.chosen,
    };
    let options = PlanOptions { count: 30, candidates: 2000, seed: 5, ..PlanOptions::default() };
    let plan = plan(&input, &options).unwrap();
    let predicted = plan.poses.last().unwrap().predicted_rms.unwrap();
    let mut joints = first.joints.clone();
    joints.extend(plan.poses.iter().flat_map(|p| p.joints.clone()));
    let actual = reached_rms(&six, &robot, &joints, 13, &random_configurations(400, 21));
    errln!("six, 30 random + 30 planned: predicted RMS {predicted:.4e} mm, actual {actual:.4e} mm, ratio {:.3}", predicted / actual);
    assert!(predicted / actual < 1.5 && actual / predicted < 1.5, "predicted {predicted:.4e}, actual {actual:.4e}");
}

/// RMS error against the true positions of dh+cbd (Euler × 1) fitted on `joints` measured by `robot`.
fn reached_rms(six: &NominalModel, robot: &SixJointRobot, joints: &[f64], noise_seed: u64, test: &[f64]) -> f64 {
    let data = robot.measure(joints, noise_seed);
    let settings = crate::calibrate::Settings {
        geometry: crate::calibrate::Geometry::Calibrated,
        integrator: Some(cbd_protocol::IntegratorMethod::Euler),
        steps: Some(1),
        ..Default::default()
    };
    let cal = crate::calibrate::calibrate(six, &data, &settings).unwrap();
    let got = crate::predict::evaluate_blob(&cal.fit.blob, test).unwrap();
    let count = test.len() / 6;
    let mse: f64 = test
        .chunks_exact(6)
        .zip(got.chunks_exact(3))
        .map(|(q, y)| {
            let t = robot.true_position(q);
            (0..3).map(|c| (y[c] - t[c]).powi(2)).sum::<f64>()
        })
        .sum::<f64>()
        / count as f64;
    mse.sqrt()
}

/// The maximin design spreads the poses: on the RR torus its smallest distance between two poses
/// (around both circles) is larger than the variance planner's, every pose is chosen by it, the
/// same seed gives the same poses, and measured poses push the new ones away from them.
#[test]
fn maximin_spreads_the_poses_deterministically() {
    let nominal = crate::simulate::rr::nominal();
    let limits = [[0.0, std::f64::consts::TAU]; 2];
    let sample = candidates::uniform_within(&limits, 300, 7);
    let reach = candidates::reach(&nominal, &sample);
    let h = prior::stated(&nominal, &sample, reach, prior::StatedPrior { error: 3e-4 * reach, noise: 1e-4 });
    let input = PlanInput {
        nominal: &nominal,
        limits: &limits,
        to_model: None,
        user_candidates: &[],
        measured: None,
        hyperparameters: h.clone(),
        geometry: Geometry::Calibrated,
    };
    let options = PlanOptions { count: 24, candidates: 2000, seed: 5, workspace: 48, evaluation: 100, ..PlanOptions::default() };
    let maximin_options = PlanOptions { criterion: Criterion::Maximin, ..options.clone() };
    let full_turn = [true, true];
    let closest = |poses: &[PlannedPose]| -> f64 {
        let mut d = f64::INFINITY;
        for (i, a) in poses.iter().enumerate() {
            for b in &poses[..i] {
                d = d.min(super::joint_distance2(&a.joints, &b.joints, &full_turn).sqrt());
            }
        }
        d
    };
    let variance = plan(&input, &options).unwrap();
    let maximin = plan(&input, &maximin_options).unwrap();
    assert!(maximin.poses.iter().all(|p| p.stage == Stage::Maximin));
    // The posterior still predicts the error once the geometric group is identified.
    let identified_after = maximin.geometric_identified_after.expect("identified");
    assert!(maximin.poses[identified_after - 1..].iter().all(|p| p.predicted_rms.is_some()));
    let (dv, dm) = (closest(&variance.poses), closest(&maximin.poses));
    assert!(dm > dv, "closest pair: maximin {dm}, variance {dv}");
    // 24 points on the torus (area 4π²) cannot all be farther apart than a hexagonal packing's spacing.
    assert!(dm <= (2.0 * 4.0 * std::f64::consts::PI.powi(2) / (3f64.sqrt() * 24.0)).sqrt() + 1e-12, "{dm}");
    assert_eq!(plan(&input, &maximin_options).unwrap().poses, maximin.poses);

    // Continuing from measured poses: no new pose closer to them than the design's own spacing allows.
    let measured_joints: Vec<f64> = maximin.poses[..12].iter().flat_map(|p| p.joints.clone()).collect();
    let data = crate::simulate::rr::RealRr::default().measure(&measured_joints);
    let more = plan(&PlanInput { measured: Some(&data), ..input }, &PlanOptions { count: 12, ..maximin_options }).unwrap();
    let to_measured =
        |q: &[f64]| measured_joints.chunks_exact(2).map(|h| super::joint_distance2(q, h, &full_turn).sqrt()).fold(f64::INFINITY, f64::min);
    assert!(more.poses.iter().all(|p| to_measured(&p.joints) >= dm * 0.999), "a new pose sits on a measured one");
}

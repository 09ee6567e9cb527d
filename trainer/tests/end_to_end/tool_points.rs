//! Issue 26 item 1's done-when, trainer side: the simulated six-joint arm (`cbd simulate --robot
//! six`: geometric errors and gravity joint compliance) measured at three tool points 100 mm apart,
//! noise 0.02 mm per coordinate, 300 training and 1000 test poses, through `cbd compare`:
//! - dh+cbd's error at the tool origin (point 1, the point today's single-point data measure) no
//!   worse than today's single-point dh+cbd on the same configurations (`cbd fit --dh-first`);
//! - the orientation error reported for every method and, for dh+cbd, ≤ 2× what the test noise
//!   alone gives (docs/DESIGN.md §12: RMS √5 σ/s for three points on an equilateral triangle of side s);
//! - pose compensation (`Calibrator::compensate_pose`) of the dh+cbd model: the simulated arm's true
//!   tool frame after the command within 1.2× of the model's forward error in position and
//!   orientation, and ahead of DH (Gauss–Newton on the DH-calibrated chain's tool frame);
//!   `cbd compensate` without seeds reaches ≥ 98 % of 200 measured poses;
//! - the same poses given as position + quaternion columns give the same model to 1e-9 mm (the
//!   simulator writes the point columns as the points of the pose it writes: the same data).

use crate::cli_support;
use cli_support::{examples, json, run, scratch};

const TOOL_POINTS: &str = "0,0,0;100,0,0;50,86.60254037844386,0";
const NOISE: f64 = 0.02;
const SIDE: f64 = 100.0;

#[test]
fn three_tool_points_calibrate_position_and_orientation() {
    let dir = scratch("tool-points");
    let six = |count: &str, seed: &str, extra: &[&str], out: &str| {
        let mut args = vec!["simulate", "--robot", "six", "--sampling", "uniform", "--count", count, "--seed", seed, "--noise", "0.02"];
        args.extend_from_slice(extra);
        args.extend_from_slice(&["--out", out]);
        run(&dir, &args);
    };
    six("300", "1", &["--tool-points", TOOL_POINTS], "points-train.csv");
    six("1000", "2", &["--tool-points", TOOL_POINTS], "points-test.csv");
    six("300", "1", &[], "single-train.csv");
    six("1000", "2", &[], "single-test.csv");
    let points_model = examples().join("tool-points/six-points.toml");
    let points_model = points_model.to_str().unwrap();

    // Today's single-point figure: DH, then CbD, on the same configurations.
    let ur5 = examples().join("ur5/ur5.toml");
    let ur5 = ur5.to_str().unwrap();
    run(&dir, &["fit", "--quiet", "--dh-first", "--model", ur5, "--data", "single-train.csv", "--out", "single.blob"]);
    run(&dir, &["eval", "--model", ur5, "--blob", "single.blob", "--data", "single-test.csv", "--json", "single.json"]);
    let single = json(&dir.join("single.json"))["calibrated"]["mean"].as_f64().unwrap();

    let table = run(
        &dir,
        &["compare", "--model", points_model, "--train", "points-train.csv", "--test", "points-test.csv", "--json", "points.json"],
    );
    println!("{table}\nsingle-point dh+cbd (cbd fit --dh-first): {single:.4e} mm");
    let methods = json(&dir.join("points.json"))["methods"].clone();
    let pose = |name: &str| methods[name]["pose"].clone();
    // Orientation of a least-squares frame from three points with σ per coordinate: covariance
    // σ² (Σ_j [c_j]ₓᵀ[c_j]ₓ)⁻¹ = σ² diag(2, 2, 1)/s² for an equilateral triangle of side s (§12).
    let noise_rms_deg = (5.0f64).sqrt() * NOISE / SIDE * 180.0 / std::f64::consts::PI;
    for name in ["nominal", "dh", "krr", "dh+krr", "cbd", "dh+cbd"] {
        let p = pose(name);
        assert_eq!(p["points"].as_array().map(Vec::len), Some(3), "{name}: per-point errors");
        assert!(p["orientation_deg"]["mean"].as_f64().is_some_and(f64::is_finite), "{name}: orientation reported");
    }
    let hybrid = pose("dh+cbd");
    let origin = hybrid["points"][0]["mean"].as_f64().unwrap();
    assert!(origin <= single, "dh+cbd at the tool origin {origin:.4e} mm; single-point dh+cbd {single:.4e} mm");
    let orientation_rms = hybrid["orientation_rms_deg"].as_f64().unwrap();
    println!("dh+cbd orientation RMS {orientation_rms:.4e}°; the test noise alone {noise_rms_deg:.4e}°");
    assert!(orientation_rms <= 2.0 * noise_rms_deg, "{orientation_rms}° against 2 × {noise_rms_deg}°");
    // Below the noise's own level is impossible (the test frames carry it): a check of the bound.
    assert!(orientation_rms >= 0.9 * noise_rms_deg, "{orientation_rms}° below the test noise's {noise_rms_deg}°");
    // DH+CbD is ahead of DH and of kernel ridge in position and orientation.
    for other in ["dh", "dh+krr", "krr", "cbd"] {
        assert!(methods["dh+cbd"]["mean"].as_f64() < methods[other]["mean"].as_f64(), "dh+cbd against {other}");
        assert!(
            hybrid["orientation_rms_deg"].as_f64() <= pose(other)["orientation_rms_deg"].as_f64(),
            "orientation: dh+cbd against {other}"
        );
    }

    run(&dir, &["fit", "--quiet", "--dh-first", "--model", points_model, "--data", "points-train.csv", "--out", "points.blob"]);
    commanded_poses(&std::fs::read(dir.join("points.blob")).unwrap());
    // `cbd compensate` without seeds: the hints are the nearest training poses, tried in turn. The
    // nearest alone left 4 of 50 targets unreached (9 mm, 15° off, on branches near the elbow's
    // singularity); 2 % is what targets within a few degrees of it still cost.
    six("200", "4", &["--tool-points", TOOL_POINTS], "targets.csv");
    run(
        &dir,
        &[
            "compensate",
            "--model",
            points_model,
            "--blob",
            "points.blob",
            "--targets",
            "targets.csv",
            "--out",
            "commands.csv",
            "--json",
            "commands.json",
        ],
    );
    let reached = json(&dir.join("commands.json"))["reached"].as_u64().unwrap();
    println!("cbd compensate without seeds: {reached} of 200 target poses reached");
    assert!(reached >= 196, "{reached} of 200 reached without seeds");

    // The same poses as position + quaternion columns (`--pose` writes both column sets): one model.
    six("40", "3", &["--tool-points", TOOL_POINTS, "--pose"], "pose-train.csv");
    let pose_model = examples().join("tool-points/six-pose.toml");
    for (model, blob) in [(points_model, "from-points.blob"), (pose_model.to_str().unwrap(), "from-pose.blob")] {
        run(&dir, &["fit", "--quiet", "--dh-first", "--model", model, "--data", "pose-train.csv", "--out", blob]);
    }
    let test_joints: Vec<f64> = cbd_trainer::simulate::six_joint::random_configurations(200, 4)
        .chunks_exact(6)
        .flat_map(|q| std::iter::repeat(q.to_vec()).take(3).flatten())
        .collect();
    let predict = |blob: &str| cbd_trainer::predict::evaluate_blob(&std::fs::read(dir.join(blob)).unwrap(), &test_joints).unwrap();
    let (a, b) = (predict("from-points.blob"), predict("from-pose.blob"));
    let gap = a.iter().zip(&b).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max);
    println!("points vs pose columns: largest difference of the calibrated points {gap:.3e} mm");
    assert!(gap <= 1e-9, "{gap}");
}

/// The simulated arm's true tool frame (origin, rotation) at command `q`: its real chain at the
/// joints gravity deflects `q` to (the arm `cbd simulate --robot six` measures).
fn true_frame(robot: &cbd_trainer::simulate::six_joint::SixJointRobot, q: &[f64]) -> Frame {
    let walk = cbd_runtime::internals::kinematics::rigid::dh_walk(&robot.real, &robot.deflected(q));
    Frame::new(walk.tool_rotation, walk.tool)
}

use cbd_trainer::nominal::tool_points::rotation_angle;
use cbd_trainer::nominal::Frame;

/// Mean position (mm) and orientation (degrees) error of `frames` against `truth`.
fn mean_errors(frames: &[Frame], truth: &[Frame]) -> (f64, f64) {
    let count = frames.len() as f64;
    let position = frames
        .iter()
        .zip(truth)
        .map(|(a, b)| {
            cbd_runtime::internals::kinematics::spatial::norm(cbd_runtime::internals::kinematics::spatial::sub(
                a.translation(),
                b.translation(),
            ))
        })
        .sum::<f64>();
    let angle = frames.iter().zip(truth).map(|(a, b)| rotation_angle(a, b).to_degrees()).sum::<f64>();
    (position / count, angle / count)
}

/// Levenberg–Marquardt on `model`'s tool frame (the DH-calibrated chain), from `seed`: the pose
/// error e = (t* − t(q), L · rotation vector of R* R(q)ᵀ), L = 57.7 mm (the tool points' RMS lever),
/// steps (JᵀJ + λI)⁻¹Jᵀe kept only when |e| falls (λ adapted), 40 iterations.
fn dh_pose_command(model: &cbd_protocol::NominalModel, target: &Frame, seed: &[f64]) -> Vec<f64> {
    use cbd_runtime::internals::kinematics::tool_point::nominal_tool_frame;
    const LEVER: f64 = 57.735;
    let error = |q: &[f64]| -> Option<(Vec<f64>, [[f64; cbd_protocol::MAX_JOINTS]; 6])> {
        let (fit, jac) = nominal_tool_frame(model, q)?;
        let current = Frame::new(fit.rotation, fit.origin);
        let (axis, angle) = cbd_trainer::nominal::rigid_fit::axis_angle(&current.inverse().compose(target));
        let world_axis = current.rotate(axis);
        let e = (0..3).map(|a| target.translation()[a] - fit.origin[a]).chain((0..3).map(|a| LEVER * world_axis[a] * angle)).collect();
        Some((e, jac))
    };
    let norm = |e: &[f64]| e.iter().map(|v| v * v).sum::<f64>();
    let mut q = seed.to_vec();
    let mut lambda = 1e-3;
    for _ in 0..40 {
        let Some((e, jac)) = error(&q) else { break };
        let j = faer::Mat::<f64>::from_fn(6, 6, |r, d| if r < 3 { jac[r][d] } else { LEVER * jac[r][d] });
        let rhs = j.transpose() * faer::Mat::<f64>::from_fn(6, 1, |r, _| e[r]);
        loop {
            let lhs = j.transpose() * &j + faer::Mat::<f64>::identity(6, 6) * lambda;
            let dq = faer::linalg::solvers::Solve::solve(&lhs.partial_piv_lu(), &rhs);
            let trial: Vec<f64> = (0..6).map(|d| q[d] + dq[(d, 0)]).collect();
            match error(&trial) {
                Some((et, _)) if norm(&et) < norm(&e) => {
                    q = trial;
                    lambda = (lambda / 3.0).max(1e-12);
                    break;
                }
                _ if lambda < 1e12 => lambda *= 4.0,
                _ => return q,
            }
        }
    }
    q
}

/// Pose compensation on the simulated arm: 200 reachable target poses (its true tool frames at
/// random configurations), seeds 0.05 rad away.
fn commanded_poses(blob: &[u8]) {
    use rand::{Rng, SeedableRng};
    let robot = cbd_trainer::simulate::six_joint::SixJointRobot::ur5_like(1);
    let model = cbd_protocol::decode(blob).unwrap();
    let dh = model.nominal.clone();
    let mut storage = vec![0.0; cbd_runtime::storage_len_for(&model)];
    let mut cal = cbd_runtime::Calibrator::from_model(model, &mut storage).unwrap();
    let configurations = cbd_trainer::simulate::six_joint::random_configurations(200, 9);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(10);
    let (mut truth, mut forward, mut commanded, mut by_dh) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let mut reached = 0;
    for q_star in configurations.chunks_exact(6) {
        let target = true_frame(&robot, q_star);
        let pose = cal.evaluate_pose(q_star).unwrap();
        forward.push(Frame::new(pose.rotation(), pose.origin()));
        let seed: Vec<f64> = q_star.iter().map(|q| q + rng.gen_range(-0.05..0.05)).collect();
        let mut q = [0.0; 6];
        let result = cal.compensate_pose(&target.translation(), &target.rotation(), &seed, &mut q).unwrap();
        reached += result.reached as usize;
        commanded.push(true_frame(&robot, &q));
        by_dh.push(true_frame(&robot, &dh_pose_command(&dh, &target, &seed)));
        truth.push(target);
    }
    let (forward, commanded, by_dh) = (mean_errors(&forward, &truth), mean_errors(&commanded, &truth), mean_errors(&by_dh, &truth));
    println!(
        "pose compensation, 200 targets ({reached} reached): dh+cbd commanded {:.4e} mm, {:.4e}° (forward {:.4e} mm, {:.4e}°); DH {:.4e} mm, {:.4e}°",
        commanded.0, commanded.1, forward.0, forward.1, by_dh.0, by_dh.1
    );
    assert!(commanded.0 <= 1.2 * forward.0 && commanded.1 <= 1.2 * forward.1, "commanded {commanded:?} against forward {forward:?}");
    assert!(commanded.0 < by_dh.0 && commanded.1 < by_dh.1, "commanded {commanded:?} against DH {by_dh:?}");
}

//! Issue 26 item 2, the hidden-frame test: the simulated six-joint arm's data moved by 4 m and
//! turned by 30° about a tilted axis (a tracker's frame), the base declared unknown
//! (`[chain] base = { register = true }`), against the declared-base run on the original data.

use cbd_protocol::NominalModel;
use cbd_trainer::baselines::kernel_ridge::{kernel_ridge_correction, SearchOptions};
use cbd_trainer::data::model_file::{load_model_file, parse_model_file};
use cbd_trainer::data::Measurements;
use cbd_trainer::evaluation::compare::{compare_peers, Comparison};
use cbd_trainer::face::peers::{CBD, KRR};
use cbd_trainer::nominal::rigid_fit::axis_angle;
use cbd_trainer::nominal::{rotation_about, Frame};
use cbd_trainer::parametric::base_registration::{folded_base, register_and_refine, register_base};
use cbd_trainer::simulate::six_joint::{random_configurations, SixJointRobot};

fn moved(data: &Measurements, motion: &Frame) -> Measurements {
    let mut out = Measurements::new(data.n_joints, 3);
    for i in 0..data.len() {
        let y = data.position(i);
        out.push(data.joints(i), &motion.apply([y[0], y[1], y[2]]));
    }
    out
}

fn base_of(model: &NominalModel) -> Frame {
    let NominalModel::DhChain(c) = model else { panic!("a DH chain") };
    Frame::from_transform(&c.base)
}

/// The simulated arm's own base (±1 mm, ±0.05°) seen from the hidden frame, with its joint 1's θ
/// offset and d folded in: base yaw vs θ₁ and base z vs d₁ are one thing to any data, and
/// `folded_base` is how the registration answers them.
fn true_base_in(robot: &SixJointRobot, nominal: &NominalModel, motion: &Frame) -> Frame {
    let NominalModel::DhChain(nominal_chain) = nominal else { panic!("a DH chain") };
    let mut real = robot.real.clone();
    real.base = motion.compose(&Frame::from_transform(&robot.real.base)).to_transform();
    folded_base(nominal_chain, &real)
}

/// Distance (mm) and angle (degrees) between two frames.
fn gap(got: &Frame, want: &Frame) -> (f64, f64) {
    let mm = (0..3).map(|k| (got.translation()[k] - want.translation()[k]).powi(2)).sum::<f64>().sqrt();
    (mm, axis_angle(&want.inverse().compose(got)).1.to_degrees())
}

/// Joint 1's axis (the base's z axis through its origin) of `got` against `want`'s: distance of
/// `got`'s origin from `want`'s axis line (mm), angle between the axes (degrees), and the offset
/// along the axis (mm).
fn axis_gap(got: &Frame, want: &Frame) -> (f64, f64, f64) {
    let d = want.inverse().apply(got.translation());
    let z = want.inverse().rotate([got.rotation()[0][2], got.rotation()[1][2], got.rotation()[2][2]]);
    ((d[0] * d[0] + d[1] * d[1]).sqrt(), z[2].clamp(-1.0, 1.0).acos().to_degrees(), d[2])
}

/// With geometric errors only (no gravity sag) the data define the whole base: the registered
/// base in a hidden frame is within 0.05 mm / 0.005° of the true one (all six degrees of
/// freedom, joint 1's offset and d folded in), and the rigid fit alone is not.
#[test]
fn the_registered_base_of_a_rigid_arm_is_the_true_one() {
    let mut robot = SixJointRobot::ur5_like(7);
    robot.compliance = [0.0; 6];
    let motion = rotation_about([0.0, 0.6, 0.8], -0.4).with_translation([-2500.0, 3000.0, 1200.0]);
    let train = moved(&robot.measure(&random_configurations(200, 1), 11), &motion);
    let nominal = robot.nominal.clone();
    let truth = true_base_in(&robot, &nominal, &motion);
    let mut registered = nominal.clone();
    register_and_refine(&mut registered, &train).unwrap();
    let (mm, deg) = gap(&base_of(&registered), &truth);
    let mut rigid = nominal.clone();
    register_base(&mut rigid, &train).unwrap();
    let (rigid_mm, rigid_deg) = gap(&base_of(&rigid), &truth);
    eprintln!("registered base vs the true one: {mm:.3e} mm, {deg:.3e}° (rigid fit alone: {rigid_mm:.3e} mm, {rigid_deg:.3e}°)");
    assert!(mm < 0.05 && deg < 0.005, "{mm} mm, {deg}°");
    assert!(rigid_mm > mm && rigid_deg > deg, "the refinement gains nothing?");
}

/// The comparison with CbD at fixed hyperparameters (no evidence search: the test stays fast;
/// both runs use the same ones).
fn compare(nominal: &NominalModel, train: &Measurements, test: &Measurements) -> Comparison {
    let settings = cbd_trainer::calibrate::Settings {
        overrides: cbd_trainer::calibrate::Overrides {
            sigma: Some(0.02),
            task_width: Some(800.0),
            task_gamma: Some(1.0),
            joint_b: Some(1.0),
            joint_gamma: Some(1e-4),
        },
        steps: Some(1),
        integrator: Some(cbd_protocol::IntegratorMethod::Euler),
        ..Default::default()
    };
    let fitter = cbd_trainer::face::peers::cbd_correction(&settings);
    let search = SearchOptions::default();
    let krr = kernel_ridge_correction(&search);
    compare_peers(nominal, train, test, &[KRR.with(&krr), CBD.with(&fitter)])
}

#[test]
fn data_in_a_hidden_frame_give_the_declared_base_figures_and_the_registered_base() {
    let robot = SixJointRobot::ur5_like(7);
    let train = robot.measure(&random_configurations(200, 1), 11);
    let test = robot.measure(&random_configurations(300, 2), 12);
    // 4 m away along a tilted direction, turned by 30° about a tilted axis.
    let n = |v: [f64; 3]| {
        let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        v.map(|x| x / l)
    };
    let axis = n([1.0, -2.0, 3.0]);
    let motion = rotation_about(axis, 30f64.to_radians()).with_translation(n([2.0, 1.0, -0.5]).map(|x| 4000.0 * x));
    let (train_moved, test_moved) = (moved(&train, &motion), moved(&test, &motion));

    let declared = load_model_file(concat!(env!("CARGO_MANIFEST_DIR"), "/../examples/ur5/ur5.toml")).unwrap();
    let text = std::fs::read_to_string(&declared.path)
        .unwrap()
        .replace("base = { translation = [0, 0, 0], rpy = [0, 0, 0] }", "base = { register = true }");
    let unknown = parse_model_file(&text, &declared.path).unwrap();
    assert!(unknown.register_base && !declared.register_base);

    let mut registered = unknown.nominal.clone();
    let r = register_and_refine(&mut registered, &train_moved).unwrap();
    eprintln!("{}", r.describe("mm"));
    assert!(r.refined);
    let truth = true_base_in(&robot, &unknown.nominal, &motion);
    let got = base_of(&registered);
    // The arm sags under gravity (≈ 0.1 mm at the tool): the mean sag is a shift along the
    // vertical base axis that no geometric model tells from the base's height, so here the
    // joint-1 axis (4 of the base's 6 degrees of freedom) is what the data define; the
    // geometric-only arm below checks all six.
    let (off_axis_mm, tilt_deg, along_mm) = axis_gap(&got, &truth);
    eprintln!("registered joint-1 axis vs the true one: {off_axis_mm:.3e} mm off, {tilt_deg:.3e}° tilt; {along_mm:.3e} mm along it (the mean gravity sag)");
    assert!(off_axis_mm < 0.05 && tilt_deg < 0.005, "{off_axis_mm} mm, {tilt_deg}°");
    let mut rigid = unknown.nominal.clone();
    register_base(&mut rigid, &train_moved).unwrap();
    let (rigid_mm, rigid_deg, _) = axis_gap(&base_of(&rigid), &truth);
    eprintln!("rigid fit alone: {rigid_mm:.3e} mm off, {rigid_deg:.3e}° tilt");
    // Registration commutes with the frame: at home it finds the same base, carried by the motion.
    let mut at_home = unknown.nominal.clone();
    register_and_refine(&mut at_home, &train).unwrap();
    let (eq_mm, eq_deg) = gap(&got, &motion.compose(&base_of(&at_home)));
    assert!(eq_mm < 1e-3 && eq_deg < 1e-4, "{eq_mm} mm, {eq_deg}°");
    assert!(r.rms_before > 1000.0 && r.rms_after < 5.0, "{r:?}");

    // Every method: the registered run on the moved data against the declared run at home.
    let home = compare(&declared.nominal, &train, &test);
    let away = compare(&registered, &train_moved, &test_moved);
    for (a, b) in home.rows.iter().zip(&away.rows) {
        assert_eq!(a.name, b.name);
        let ratio = b.stats.mean / a.stats.mean;
        eprintln!("{:8} declared {:.4e} mm, registered {:.4e} mm (× {ratio:.4})", a.name, a.stats.mean, b.stats.mean);
        // The DH rows refine the base themselves: the same figures. The others start from the
        // nominal in the registered frame, which has also taken up the arm's own base error
        // (declared: identity): never worse than the declared run by 2 %, and better by less than
        // the nominal itself gained.
        if a.name.starts_with("dh") {
            assert!((ratio - 1.0).abs() < 0.02, "{}: declared {:e}, registered {:e}", a.name, a.stats.mean, b.stats.mean);
        } else {
            assert!(ratio < 1.02 && ratio > 0.75, "{}: declared {:e}, registered {:e}", a.name, a.stats.mean, b.stats.mean);
        }
    }
}

use crate::cli_support;

/// The CLI: a nominal far from the data is a warning naming the figure (declared base); with
/// the base declared unknown, `fit` registers it, says where, and the warning is gone. A base
/// both registered and given is an error naming the field.
#[test]
fn cli_registers_an_unknown_base_and_warns_about_a_far_nominal() {
    use cli_support::*;
    let dir = scratch("tracker-frame");
    let motion = rotation_about([0.0, 0.6, 0.8], 0.5).with_translation([2500.0, -3000.0, 800.0]);
    let text = std::fs::read_to_string(ur5_dir().join("train.csv")).unwrap();
    let moved_rows = |rows: std::ops::Range<usize>| {
        let mut out = format!("{}\n", text.lines().next().unwrap());
        for line in text.lines().skip(1).skip(rows.start).take(rows.len()) {
            let v: Vec<f64> = line.split(',').map(|x| x.parse().unwrap()).collect();
            let y = motion.apply([v[6], v[7], v[8]]);
            let row: Vec<String> = v[..6].iter().chain(&y).map(|x| format!("{x:?}")).collect();
            out += &(row.join(",") + "\n");
        }
        out
    };
    write(&dir, "tracker.csv", moved_rows(0..60));
    write(&dir, "tracker-test.csv", moved_rows(60..160));
    let model = std::fs::read_to_string(ur5_model()).unwrap();
    write(&dir, "declared.toml", &model);
    write(&dir, "unknown.toml", model.replace("base = { translation = [0, 0, 0], rpy = [0, 0, 0] }", "base = { register = true }"));
    write(
        &dir,
        "both.toml",
        model.replace("base = { translation = [0, 0, 0], rpy = [0, 0, 0] }", "base = { register = true, translation = [1, 2, 3] }"),
    );
    let fit = |model: &str| fit_without_search(&dir, model, "tracker.csv", "a.blob");
    let err = succeeds(&fit("declared.toml"));
    assert!(
        err.contains("warning: tracker.csv: the nominal model is 4.243e3 from the measurements (RMS)")
            && err.contains("% of their extent")
            && err.contains("register = true"),
        "{err}"
    );
    let err = succeeds(&fit("unknown.toml"));
    let fit_line = err.lines().find(|l| l.contains("registered base")).unwrap_or_default().to_string();
    assert!(
        err.contains("tracker.csv: registered base (rigid fit refined by the geometric group): translation [2499.")
            && err.contains("rotation 28."),
        "{err}"
    );
    assert!(!err.contains("warning: tracker.csv: the nominal model"), "{err}");
    fails_with(&fit("both.toml"), &["both.toml", "[chain.base]", "give either register = true or the base's pose"]);
    // diagnose reports it in its JSON (and registers on the training rows only).
    succeeds(&cbd(&dir, &["diagnose", "--no-cbd", "--model", "unknown.toml", "--data", "tracker.csv", "--json", "d.json"]));
    let d: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(dir.join("d.json")).unwrap()).unwrap();
    let angle = d["registered_base"]["angle_deg"].as_f64().unwrap();
    // The motion turned by 0.5 rad (28.648°); the arm's own base and θ₁ offset come on top (the
    // rigid fit alone said 28.56°, the refined one 28.92°: a real arm's joint-1 offset).
    let rms_after = d["registered_base"]["rms_after"].as_f64().unwrap();
    assert!((angle - 28.648).abs() < 0.5 && rms_after < 10.0 && d["registered_base"]["refined"] == true, "{d}");
    // eval reports in the registered frame too.
    let err = succeeds(&cbd(&dir, &["eval", "--model", "unknown.toml", "--blob", "a.blob", "--data", "tracker-test.csv"]));
    // eval takes the base the fit registered on its training rows (from the blob), not one
    // registered on the rows it evaluates.
    let fitted = fit_line.split("translation").nth(1).and_then(|t| t.split(';').next()).unwrap().to_string();
    assert!(err.contains(&fitted) && err.contains("(as fitted, from a.blob)"), "{err}\nwant {fitted}");
}

/// `cbd simulate --tracker-frame` (README's tracker-frame example): every point of every pose is the
/// base-frame measurement moved by the stated frame (same noise draws), and bad frames are refused
/// naming the flag.
#[test]
fn simulate_writes_the_measurements_in_the_tracker_frame() {
    use cli_support::{cbd, fails_with, scratch, succeeds};
    let dir = scratch("tracker_frame_simulate");
    let common = ["simulate", "--robot", "six", "--sampling", "uniform", "--count", "20", "--tool-points", "0,0,0;100,0,0;0,100,0"];
    succeeds(&cbd(&dir, &[&common[..], &["--out", "base.csv"]].concat()));
    succeeds(&cbd(&dir, &[&common[..], &["--out", "tracker.csv", "--tracker-frame", "2500,-3000,800;0,3,4,30"]].concat()));
    let read = |name: &str| -> Vec<Vec<f64>> {
        std::fs::read_to_string(dir.join(name))
            .unwrap()
            .lines()
            .skip(1)
            .map(|l| l.split(',').map(|v| v.parse().unwrap()).collect())
            .collect()
    };
    let (base, tracker) = (read("base.csv"), read("tracker.csv"));
    let motion = rotation_about([0.0, 0.6, 0.8], 30f64.to_radians()).with_translation([2500.0, -3000.0, 800.0]);
    assert_eq!(base.len(), 20);
    for (b, t) in base.iter().zip(&tracker) {
        assert_eq!(b[..6], t[..6], "the joints are not moved");
        for j in 0..3 {
            let y = motion.apply([b[6 + 3 * j], b[7 + 3 * j], b[8 + 3 * j]]);
            for c in 0..3 {
                assert!((y[c] - t[6 + 3 * j + c]).abs() < 1e-9, "point {j}: {y:?} vs {:?}", &t[6 + 3 * j..9 + 3 * j]);
            }
        }
    }
    for bad in ["1,2,3", "1,2,3;0,0,0,30", "1,2;0,0,1,30", "1,2,3;0,0,1,nan", "a,2,3;0,0,1,3"] {
        fails_with(&cbd(&dir, &[&common[..], &["--out", "bad.csv", "--tracker-frame", bad]].concat()), &["--tracker-frame"]);
    }
    fails_with(&cbd(&dir, &["simulate", "--out", "rr.csv", "--tracker-frame", "0,0,0;0,0,1,0"]), &["--tracker-frame", "six-joint"]);
}

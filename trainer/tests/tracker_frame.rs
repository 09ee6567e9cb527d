//! Issue 26 item 2, the hidden-frame test: the simulated six-joint arm's data moved by 4 m and
//! turned by 30° about a tilted axis (a tracker's frame), the base declared unknown
//! (`[chain] base = { register = true }`), against the declared-base run on the original data.

use cbd_protocol::NominalModel;
use cbd_trainer::baselines::compare::{compare_peers, Comparison};
use cbd_trainer::data::model_file::{load_model_file, parse_model_file};
use cbd_trainer::data::Measurements;
use cbd_trainer::kernels::hyperparameters::SearchOptions;
use cbd_trainer::nominal::register::{axis_angle, register_base};
use cbd_trainer::nominal::{rotation_about, Frame};
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
        verbose: false,
        ..Default::default()
    };
    let fitter = cbd_trainer::cli::compare::cbd_fitter(&settings);
    compare_peers(nominal, train, test, &SearchOptions::default(), Some(&fitter))
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
    let r = register_base(&mut registered, &train_moved).unwrap();
    // The registered base against the hidden frame: the rigid fit also takes up the arm's own
    // base error (±1 mm, ±0.05°) and what of its DH errors looks rigid, so compare with the same
    // registration on the original data carried by the motion (the frame is all that differs).
    let mut at_home = unknown.nominal.clone();
    register_base(&mut at_home, &train).unwrap();
    let want = motion.compose(&base_of(&at_home));
    let got = base_of(&registered);
    let gap_mm = (0..3).map(|k| (got.translation()[k] - want.translation()[k]).powi(2)).sum::<f64>().sqrt();
    let (_, gap_angle) = axis_angle(&want.inverse().compose(&got));
    eprintln!("{}", r.describe("mm"));
    eprintln!("registered base vs hidden frame ∘ home registration: {gap_mm:.3e} mm, {:.3e}°", gap_angle.to_degrees());
    let (_, off_angle) = axis_angle(&motion.inverse().compose(&got));
    let off_mm = (0..3).map(|k| (got.translation()[k] - motion.translation()[k]).powi(2)).sum::<f64>().sqrt();
    eprintln!("registered base vs the hidden frame itself: {off_mm:.3e} mm, {:.3e}°", off_angle.to_degrees());
    assert!(gap_mm < 0.05 && gap_angle.to_degrees() < 0.005, "{gap_mm} mm, {}°", gap_angle.to_degrees());
    assert!(off_mm < 5.0 && off_angle.to_degrees() < 0.5, "{off_mm} mm, {}°", off_angle.to_degrees());
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

mod cli_support;

/// The CLI: a nominal far from the data is a warning naming the figure (declared base); with
/// the base declared unknown, `fit` registers it, says where, and the warning is gone. A base
/// both registered and given is an error naming the field.
#[test]
fn cli_registers_an_unknown_base_and_warns_about_a_far_nominal() {
    use cli_support::*;
    let dir = scratch("tracker-frame");
    let motion = rotation_about([0.0, 0.6, 0.8], 0.5).with_translation([2500.0, -3000.0, 800.0]);
    let text = std::fs::read_to_string(ur5_dir().join("train.csv")).unwrap();
    let mut out = String::new();
    for (k, line) in text.lines().take(61).enumerate() {
        if k == 0 {
            out += &format!("{line}\n");
            continue;
        }
        let v: Vec<f64> = line.split(',').map(|x| x.parse().unwrap()).collect();
        let y = motion.apply([v[6], v[7], v[8]]);
        let row: Vec<String> = v[..6].iter().chain(&y).map(|x| format!("{x:?}")).collect();
        out += &(row.join(",") + "\n");
    }
    write(&dir, "tracker.csv", out);
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
    assert!(err.contains("tracker.csv: registered base: translation [2499.") && err.contains("rotation 28."), "{err}");
    assert!(!err.contains("warning: tracker.csv: the nominal model"), "{err}");
    fails_with(&fit("both.toml"), &["both.toml", "[chain.base]", "give either register = true or the base's pose"]);
    // diagnose reports it in its JSON (and registers on the training rows only).
    succeeds(&cbd(&dir, &["diagnose", "--no-cbd", "--model", "unknown.toml", "--data", "tracker.csv", "--json", "d.json"]));
    let d: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(dir.join("d.json")).unwrap()).unwrap();
    let angle = d["registered_base"]["angle_deg"].as_f64().unwrap();
    assert!((angle - 28.56).abs() < 0.01 && d["registered_base"]["rms_after"].as_f64().unwrap() < 2.0, "{d}");
    // eval reports in the registered frame too.
    let err = succeeds(&cbd(&dir, &["eval", "--model", "unknown.toml", "--blob", "a.blob", "--data", "tracker.csv"]));
    assert!(err.contains("registered base:"), "{err}");
}

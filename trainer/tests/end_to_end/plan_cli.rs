//! `cbd plan` and `cbd simulate --poses` through the real binary: the loop plan → measure → plan
//! again from the data → fit, and bad inputs (exit code 1, the file and line named, no panic).

use crate::cli_support;
use cli_support::*;

#[test]
fn plan_measure_plan_again_fit() {
    let dir = scratch("plan-loop");
    succeeds(&cbd(&dir, &["plan", "--count", "12", "--candidates", "800", "--noise", "1e-4", "--out", "p1.csv"]));
    succeeds(&cbd(&dir, &["simulate", "--poses", "p1.csv", "--noise", "1e-4", "--out", "m1.csv"]));
    let err =
        succeeds(&cbd(&dir, &["plan", "--count", "8", "--candidates", "800", "--data", "m1.csv", "--out", "p2.csv", "--json", "p2.json"]));
    assert!(err.contains("predicted RMS position error after the measured poses"), "{err}");
    let json: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(dir.join("p2.json")).unwrap()).unwrap();
    let curve = json["learning_curve"].as_array().unwrap();
    assert_eq!(curve.len(), 8);
    // More poses never raise the posterior's predicted error.
    let rms: Vec<f64> = curve.iter().map(|c| c["predicted_rms"].as_f64().unwrap()).collect();
    assert!(rms.windows(2).all(|w| w[1] <= w[0] * (1.0 + 1e-9)), "{rms:?}");
    succeeds(&cbd(&dir, &["simulate", "--poses", "p2.csv", "--noise", "1e-4", "--seed", "2", "--out", "m2.csv"]));
    let m2 = std::fs::read_to_string(dir.join("m2.csv")).unwrap();
    let mut all = std::fs::read_to_string(dir.join("m1.csv")).unwrap();
    all.extend(m2.lines().skip(1).map(|l| format!("{l}\n")));
    write(&dir, "all.csv", all);
    succeeds(&cbd(&dir, &["fit", "--data", "all.csv", "--out", "arm.blob", "--steps", "1"]));

    // The space-filling criterion from the same data: its poses said in the JSON, after the data.
    succeeds(&cbd(
        &dir,
        &[
            "plan",
            "--count",
            "8",
            "--candidates",
            "800",
            "--data",
            "m1.csv",
            "--criterion",
            "maximin",
            "--out",
            "p3.csv",
            "--json",
            "p3.json",
        ],
    ));
    let json: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(dir.join("p3.json")).unwrap()).unwrap();
    assert_eq!(json["criterion"], "maximin");
    let stages: Vec<&str> = json["plan"]["poses"].as_array().unwrap().iter().map(|p| p["stage"].as_str().unwrap()).collect();
    assert_eq!(stages, ["maximin"; 8], "every pose by the criterion");
    fails_with(
        &cbd(&dir, &["plan", "--count", "8", "--criterion", "maximin", "--exchange", "1", "--out", "p4.csv"]),
        &["--exchange", "--criterion maximin"],
    );
}

#[test]
fn bad_plan_inputs_name_the_file_and_line() {
    let dir = scratch("plan-errors");
    let model = ur5_dir().join("simulated-six.toml").to_str().unwrap().to_string();
    write(&dir, "cand.csv", "q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg\n0,-90,10,0,30,0\n0,45,10,0,30,0\n");
    fails_with(
        &cbd(&dir, &["plan", "--model", &model, "--count", "2", "--candidates", "50", "--candidate-file", "cand.csv", "--out", "o.csv"]),
        &["cand.csv:3", "q2_deg", "outside the joint's range"],
    );
    write(&dir, "poses.csv", "q1,q2\n0.1,zz\n");
    fails_with(&cbd(&dir, &["simulate", "--poses", "poses.csv", "--out", "m.csv"]), &["poses.csv:2", "'q2'"]);
    fails_with(&cbd(&dir, &["plan", "--count", "100", "--candidates", "50", "--out", "o.csv"]), &["raise --candidates"]);
    fails_with(
        &cbd(&dir, &["plan", "--count", "2", "--out", "cand.csv", "--candidate-file", "cand.csv"]),
        &["cand.csv", "is also an input"],
    );
    write(&dir, "prismatic.toml", "length_unit = \"m\"\nangle_unit = \"rad\"\n[chain]\nconvention = \"standard\"\njoints = [{ a = 0.5, alpha = 0, d = 0 }, { a = 0, alpha = 0, d = 0, kind = \"prismatic\" }]\n[measurements]\njoints = [\"q1\", \"d2\"]\npositions = [\"x\", \"y\", \"z\"]\n");
    fails_with(
        &cbd(&dir, &["plan", "--model", "prismatic.toml", "--count", "2", "--out", "o.csv"]),
        &["prismatic.toml", "joint 2 has no finite limits"],
    );
    let points = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples/tool-points/six-points.toml");
    fails_with(
        &cbd(&dir, &["plan", "--model", points.to_str().unwrap(), "--count", "2", "--out", "o.csv"]),
        &["six-points.toml", "3 tool points", "one measured point per pose"],
    );
}

/// With `[measurements.joint_map]` the limits apply to the controller's values, so the plan samples
/// there, checks the model's joints for singular configurations and writes the controller's
/// values: here the controller's J5 is the model's q5 + 90°, its range [80°, 100°], so the model's
/// wrist is within 10° of its singular q5 = 0 and about a tenth of the candidates are left out.
#[test]
fn plan_writes_the_controllers_values_through_a_joint_map() {
    let dir = scratch("plan-joint-map");
    let model = std::fs::read_to_string(ur5_dir().join("simulated-six.toml")).unwrap();
    let model =
        model.replace("[-180, 180], [-180, 180]]", "[80, 100], [-180, 180]]") + "\n[measurements.joint_map]\noffset = { q5 = -90 }\n";
    write(&dir, "mapped.toml", model);
    succeeds(&cbd(
        &dir,
        &[
            "plan",
            "--model",
            "mapped.toml",
            "--count",
            "12",
            "--candidates",
            "1000",
            "--noise",
            "0.02",
            "--out",
            "p.csv",
            "--json",
            "p.json",
        ],
    ));
    let text = std::fs::read_to_string(dir.join("p.csv")).unwrap();
    let j5: Vec<f64> = text.lines().skip(1).map(|l| l.split(',').nth(4).unwrap().parse().unwrap()).collect();
    assert_eq!(j5.len(), 12);
    assert!(j5.iter().all(|v| (80.0..=100.0).contains(v) && (v - 90.0).abs() > 0.9), "{j5:?}");
    let json: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(dir.join("p.json")).unwrap()).unwrap();
    let rejected = json["plan"]["rejected_singular"].as_u64().unwrap();
    assert!(rejected >= 70, "{rejected} of 1000 candidates left out as singular (about 3 % without the map)");
}

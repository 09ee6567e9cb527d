//! `cbd diagnose` on data with three tool points per pose (issue 26 item 1): the simulated
//! six-joint arm (`cbd simulate --robot six`: geometric errors) with gravity compliance on joint 3
//! and a second-harmonic transmission error on joint 2, declared nowhere, noise 0.02 mm per
//! coordinate, measured once at three tool points 100 mm apart and once at the tool origin alone
//! (the same configurations). Diagnose names the same effects on both and invents none; the
//! transmission's estimate from three points is at least as precise (standard error) and within
//! 3 standard errors of the truth; the held-out table reports each point and the tool frame; and
//! `--write-model` keeps the tool points: `cbd eval`'s nominal error of the written model equals the
//! diagnosed "+ effects" row.

use crate::cli_support;
use cli_support::{examples, json, run, scratch};

const TOOL_POINTS: &str = "0,0,0;100,0,0;50,86.60254037844386,0";
const GRAVITY: &str = "gravity_compliance:joint=3,compliance=4e-7";
/// cos 2e-4 rad, sin −1e-4 rad: about 0.17 mm at the tool.
const TRANSMISSION: &str = "transmission:joint=2,harmonic=2,cos=2e-4,sin=-1e-4";
const TRUE_TRANSMISSION_RAD: [f64; 2] = [2e-4, -1e-4];

/// The physical effects found, as (type, joint, harmonic), sorted.
fn named(d: &serde_json::Value) -> Vec<(String, u64, u64)> {
    let mut out: Vec<(String, u64, u64)> = d["found"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|f| f["type"] != "geometric")
        .map(|f| (f["type"].as_str().unwrap().to_string(), f["joint"].as_u64().unwrap(), f["harmonic"].as_u64().unwrap_or(0)))
        .collect();
    out.sort();
    out
}

/// The transmission's (cos, sin) as (value, standard error), in radians.
fn transmission(d: &serde_json::Value) -> [(f64, f64); 2] {
    let t = d["found"].as_array().unwrap().iter().find(|f| f["type"] == "transmission").unwrap_or_else(|| panic!("{d}"));
    std::array::from_fn(|k| {
        let p = &t["parameters"][k];
        let to_rad = match p["unit"].as_str() {
            Some("deg") => 1f64.to_radians(),
            Some("rad") => 1.0,
            other => panic!("unit {other:?}"),
        };
        (p["value"].as_f64().unwrap() * to_rad, p["std_error"].as_f64().unwrap() * to_rad)
    })
}

#[test]
fn three_tool_points_name_the_same_effects_and_estimate_them_at_least_as_precisely() {
    let dir = scratch("diagnose-tool-points");
    let six = |count: &str, seed: &str, points: bool, out: &str| {
        let mut args = vec!["simulate", "--robot", "six", "--sampling", "uniform", "--count", count, "--seed", seed, "--noise", "0.02"];
        args.extend_from_slice(&["--effect", GRAVITY, "--effect", TRANSMISSION]);
        if points {
            args.extend_from_slice(&["--tool-points", TOOL_POINTS]);
        }
        args.extend_from_slice(&["--out", out]);
        run(&dir, &args);
    };
    six("300", "1", true, "points-train.csv");
    six("1000", "2", true, "points-test.csv");
    six("300", "1", false, "single-train.csv");
    six("1000", "2", false, "single-test.csv");
    let points_model = examples().join("tool-points/six-points.toml");
    let ur5 = examples().join("ur5/ur5.toml");
    let diagnose = |model: &std::path::Path, data: &str, test: &str, out: &str, extra: &[&str]| -> (String, serde_json::Value) {
        let mut args = vec!["diagnose", "--no-cbd", "--model", model.to_str().unwrap(), "--data", data, "--test", test, "--json", out];
        args.extend_from_slice(extra);
        let text = run(&dir, &args);
        (text, json(&dir.join(out)))
    };
    let (text, points) = diagnose(&points_model, "points-train.csv", "points-test.csv", "points.json", &["--write-model", "written.toml"]);
    let (_, single) = diagnose(&ur5, "single-train.csv", "single-test.csv", "single.json", &[]);
    println!("{text}");

    // The same effects on both, exactly the injected ones.
    let expected = vec![("gravity_compliance".to_string(), 3, 0), ("transmission".to_string(), 2, 2)];
    assert_eq!(named(&single), expected, "single point: {single}");
    assert_eq!(named(&points), expected, "three points: {points}");

    // The transmission: from three points at least as precise, and within 3 SE of the truth.
    let (p, s) = (transmission(&points), transmission(&single));
    for (k, name) in ["cos", "sin"].iter().enumerate() {
        println!(
            "transmission q2 h2 {name}: true {:.4e} rad; three points {:.4e} ± {:.2e}; one point {:.4e} ± {:.2e}",
            TRUE_TRANSMISSION_RAD[k], p[k].0, p[k].1, s[k].0, s[k].1
        );
        assert!(p[k].1 <= s[k].1, "{name}: standard error {} from three points, {} from one", p[k].1, s[k].1);
        assert!(
            (p[k].0 - TRUE_TRANSMISSION_RAD[k]).abs() <= 3.0 * p[k].1,
            "{name}: {} ± {} against {}",
            p[k].0,
            p[k].1,
            TRUE_TRANSMISSION_RAD[k]
        );
    }

    // The held-out table per point and of the tool frame (orientation in degrees).
    let held = &points["held_out"];
    for row in ["nominal", "nominal + geometric", "nominal + effects"] {
        assert_eq!(held[row]["pose"]["points"].as_array().map(Vec::len), Some(3), "{row}: {held}");
        assert!(held[row]["pose"]["orientation_rms_deg"].as_f64().is_some_and(f64::is_finite), "{row}: {held}");
    }
    assert!(text.contains("held-out mean error per tool point and of the tool frame"), "{text}");
    let orientation = |row: &str| held[row]["pose"]["orientation_rms_deg"].as_f64().unwrap();
    assert!(orientation("nominal + effects") < orientation("nominal + geometric"), "{held}");

    // The written model keeps the tool points and reproduces the "+ effects" row under `cbd eval`.
    let file = cbd_trainer::data::model_file::load_model_file(dir.join("written.toml")).unwrap();
    assert_eq!(file.nominal.tool_point_count(), 3);
    assert!(!file.nominal.effects().list.is_empty());
    run(&dir, &["fit", "--quiet", "--model", "written.toml", "--data", "points-train.csv", "--out", "written.blob"]);
    run(&dir, &["eval", "--model", "written.toml", "--blob", "written.blob", "--data", "points-test.csv", "--json", "eval.json"]);
    let eval = json(&dir.join("eval.json"));
    let (written, diagnosed) = (eval["nominal"]["mean"].as_f64().unwrap(), held["nominal + effects"]["mean"].as_f64().unwrap());
    println!("written model under cbd eval {written:.12e} mm; diagnosed nominal + effects {diagnosed:.12e} mm");
    assert!((written - diagnosed).abs() <= 1e-9 * diagnosed, "{written} vs {diagnosed}");
    std::fs::remove_dir_all(&dir).ok();
}

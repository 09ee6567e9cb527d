//! Issue 38: `cbd fit` decides by CbD's own evidence whether the chain's geometry is calibrated
//! first, says so with both scores, and every error table states the noise floor.

use crate::cli_support;

use cli_support::*;
use std::path::Path;

fn json(dir: &Path, name: &str) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(dir.join(name)).unwrap()).unwrap()
}

/// The mean test error `cbd eval --json` reports for the calibrated model.
fn eval_mean(dir: &Path, model: &str, blob: &str, data: &str) -> f64 {
    succeeds(&cbd(dir, &["eval", "--model", model, "--blob", blob, "--data", data, "--json", "eval.json"]));
    json(dir, "eval.json")["calibrated"]["mean"].as_f64().unwrap()
}

fn simulate_six(dir: &Path, extra: &[&str], count: &str, seed: &str, out: &str) {
    let args = [
        &["simulate", "--robot", "six", "--sampling", "uniform", "--count", count, "--seed", seed, "--noise", "0.02"][..],
        extra,
        &["--out", out],
    ]
    .concat();
    succeeds(&cbd(dir, &args));
}

/// The simulated six-joint arm (geometric errors + gravity compliance, σ = 0.02 mm, 300 poses): the
/// default is the calibrated geometry by the evidence — the `--geometry calibrated` (= `--dh-first`)
/// blob byte for byte, 11 × better than CbD on the nominal — and the tables put it at the noise floor.
#[test]
fn a_serial_arm_with_geometric_errors_is_calibrated_first_by_default() {
    let dir = scratch("geometry-six");
    let model = ur5_dir().join("simulated-six.toml").to_str().unwrap().to_string();
    simulate_six(&dir, &[], "300", "1", "train.csv");
    simulate_six(&dir, &[], "1000", "2", "test.csv");
    let out = cbd(&dir, &["fit", "--model", &model, "--data", "train.csv", "--out", "auto.blob", "--json", "auto.json"]);
    let err = succeeds(&out);
    let stdout = String::from_utf8_lossy(&out.stdout).to_string();
    let g = &json(&dir, "auto.json")["geometry"];
    assert_eq!((g["chosen"].as_str(), g["by"].as_str()), (Some("calibrated"), Some("evidence")), "{g}");
    let (nominal, calibrated) = (g["scores"]["nominal"].as_f64().unwrap(), g["scores"]["calibrated"].as_f64().unwrap());
    assert!(calibrated > nominal + 1000.0, "{g}");
    assert!(err.contains("geometry: calibrated (by evidence: log evidence nominal"), "{err}");
    // The fit states the floor and its held-out error at it.
    assert!(stdout.contains("noise floor: σ = ") && stdout.contains("at the noise floor"), "{stdout}");
    succeeds(&cbd(
        &dir,
        &["fit", "--quiet", "--geometry", "calibrated", "--model", &model, "--data", "train.csv", "--out", "calibrated.blob"],
    ));
    succeeds(&cbd(&dir, &["fit", "--quiet", "--dh-first", "--model", &model, "--data", "train.csv", "--out", "dh-first.blob"]));
    succeeds(&cbd(&dir, &["fit", "--quiet", "--geometry", "nominal", "--model", &model, "--data", "train.csv", "--out", "nominal.blob"]));
    let read = |name: &str| std::fs::read(dir.join(name)).unwrap();
    assert!(read("auto.blob") == read("calibrated.blob") && read("auto.blob") == read("dh-first.blob"));
    let (auto, plain) = (eval_mean(&dir, &model, "auto.blob", "test.csv"), eval_mean(&dir, &model, "nominal.blob", "test.csv"));
    eprintln!("six, 300 poses: default {auto:.4e} mm, --geometry nominal {plain:.4e} mm");
    assert!(auto < 0.04 && plain > 5.0 * auto, "default {auto}, nominal {plain}");
    // eval against the σ the blob records: at the floor.
    let e = json(&dir, "eval.json");
    assert!(e["noise_floor"]["floor"]["sigma"].as_f64().is_some(), "{e}");
    // compare: the floor within 10 % of the true one (0.02 mm per coordinate: 0.0319 mm), dh+cbd at
    // it and marked as what `cbd fit` writes, CbD on the nominal above it.
    let out = cbd(&dir, &["compare", "--model", &model, "--train", "train.csv", "--test", "test.csv", "--json", "compare.json"]);
    succeeds(&out);
    let table = String::from_utf8_lossy(&out.stdout).to_string();
    let c = json(&dir, "compare.json");
    let floor = c["noise_floor"]["mean_error"].as_f64().unwrap();
    let truth = 2.0 * 0.02 * (2.0 / std::f64::consts::PI).sqrt();
    eprintln!("{table}\nfloor {floor:.4e} mm against the true {truth:.4e} mm");
    assert!((floor / truth - 1.0).abs() < 0.1, "floor {floor} vs {truth}");
    assert_eq!(c["methods"]["dh+cbd"]["at_floor"], true, "{c}");
    assert_eq!(c["methods"]["cbd"]["at_floor"], false, "{c}");
    assert_eq!(c["methods"]["dh+cbd"]["written_by_fit"], true, "{c}");
    assert_eq!(c["default_fit"]["method"], "dh+cbd", "{c}");
    assert!(table.contains("dh+cbd*") && table.contains("* what `cbd fit` writes by default (dh+cbd)"), "{table}");
}

/// An arm whose nominal geometry is exact, with only a smooth joint-space effect (its gravity
/// compliance), 60 poses: the 25 geometric parameters do not pay for their Occam price, the default
/// stays on the nominal chain — the `--geometry nominal` blob byte for byte, better than calibrating.
#[test]
fn an_exact_nominal_geometry_stays_nominal() {
    let dir = scratch("geometry-exact");
    let model = ur5_dir().join("simulated-six.toml").to_str().unwrap().to_string();
    simulate_six(&dir, &["--exact-geometry"], "60", "1", "train.csv");
    simulate_six(&dir, &["--exact-geometry"], "1000", "2", "test.csv");
    succeeds(&cbd(&dir, &["fit", "--quiet", "--model", &model, "--data", "train.csv", "--out", "auto.blob", "--json", "auto.json"]));
    let g = &json(&dir, "auto.json")["geometry"];
    assert_eq!((g["chosen"].as_str(), g["by"].as_str()), (Some("nominal"), Some("evidence")), "{g}");
    succeeds(&cbd(&dir, &["fit", "--quiet", "--geometry", "nominal", "--model", &model, "--data", "train.csv", "--out", "nominal.blob"]));
    succeeds(&cbd(
        &dir,
        &["fit", "--quiet", "--geometry", "calibrated", "--model", &model, "--data", "train.csv", "--out", "calibrated.blob"],
    ));
    let read = |name: &str| std::fs::read(dir.join(name)).unwrap();
    assert!(read("auto.blob") == read("nominal.blob"));
    let (auto, calibrated) = (eval_mean(&dir, &model, "auto.blob", "test.csv"), eval_mean(&dir, &model, "calibrated.blob", "test.csv"));
    eprintln!("exact geometry, 60 poses: default {auto:.4e} mm, --geometry calibrated {calibrated:.4e} mm");
    assert!(auto < calibrated, "default {auto}, calibrated {calibrated}");
}

/// Where the choice cannot be made by the evidence or cannot be carried, the output says why: a
/// planar arm's blob holds link lengths only (the nominal, reason given, and `--geometry calibrated`
/// refused naming it); every hyperparameter given: cross-validation decides.
#[test]
fn the_choice_says_what_decided_it() {
    let dir = scratch("geometry-why");
    succeeds(&cbd(&dir, &["simulate", "--sampling", "grid", "--grid", "6", "--out", "rr.csv"]));
    succeeds(&cbd(&dir, &["fit", "--quiet", "--data", "rr.csv", "--out", "rr.blob", "--json", "rr.json"]));
    let g = &json(&dir, "rr.json")["geometry"];
    assert_eq!(g["chosen"], "nominal", "{g}");
    assert!(g["by"].as_str().unwrap().contains("holds its link lengths only"), "{g}");
    fails_with(&cbd(&dir, &["fit", "--geometry", "calibrated", "--data", "rr.csv", "--out", "c.blob"]), &["planar", "link lengths only"]);
    let model = ur5_dir().join("simulated-six.toml").to_str().unwrap().to_string();
    simulate_six(&dir, &[], "40", "3", "six.csv");
    let given = ["--sigma", "0.02", "--task-width", "800", "--task-gamma", "1", "--joint-b", "1", "--gamma", "1e-6", "--steps", "1"];
    let args =
        [&["fit", "--quiet", "--model", &model, "--data", "six.csv", "--out", "six.blob", "--json", "six.json"][..], &given[..]].concat();
    succeeds(&cbd(&dir, &args));
    let g = &json(&dir, "six.json")["geometry"];
    assert_eq!(g["by"], "4-fold cross-validation", "{g}");
    assert_eq!(g["scores"]["criterion"], "held-out RMS", "{g}");
    // `--dh-first` is `--geometry calibrated`: both at once is a usage error (exit 2) naming them.
    let both = cbd(&dir, &["fit", "--geometry", "nominal", "--dh-first", "--data", "rr.csv", "--out", "x.blob"]);
    assert_eq!(both.status.code(), Some(2));
    assert!(stderr(&both).contains("'--geometry <GEOMETRY>' cannot be used with '--dh-first'"), "{}", stderr(&both));
}

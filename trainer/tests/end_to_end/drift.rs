//! Drift named (issue 49 item 2), through the command line: `cbd simulate --sampling walk --step`
//! and `--effect drift:sd=,length=` plant a drift in measurement order along a UR5-like walk, and
//! `cbd diagnose --json` reports it (`"drift": {"detected", "sd", "length"}`), and not when the rows
//! are shuffled or none was planted; the real UR5 campaign has it. Bad specs are refused.

use crate::cli_support;

use cli_support::*;
use std::path::Path;

/// `cbd simulate --robot six` along a walk of 600 poses, steps 0.1 rad per joint (consecutive poses
/// 5–20° apart at their largest joint, like the UR5's), noise 0.02 mm, and `effects`.
fn walk(dir: &Path, name: &str, seed: u64, effects: &[&str]) -> String {
    let seed = seed.to_string();
    let mut args = vec![
        "simulate",
        "--robot",
        "six",
        "--sampling",
        "walk",
        "--step",
        "0.1",
        "--count",
        "600",
        "--noise",
        "0.02",
        "--seed",
        &seed,
        "--out",
        name,
    ];
    for e in effects {
        args.extend(["--effect", e]);
    }
    succeeds(&cbd(dir, &args));
    name.to_string()
}

/// `cbd diagnose --no-cbd --json` of the UR5 model on `data`: the JSON's `drift`.
fn drift_of(dir: &Path, data: &str) -> serde_json::Value {
    let model = ur5_model();
    let out = cbd(dir, &["diagnose", "--no-cbd", "--model", &model, "--data", data, "--json", "d.json"]);
    succeeds(&out);
    let text = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(text.contains("drift in measurement order:"), "no drift line:\n{text}");
    json(&dir.join("d.json"))["drift"].clone()
}

/// The rows of `from` (header kept) in a seeded random order.
fn shuffled(dir: &Path, from: &str, to: &str, seed: u64) -> String {
    use rand::seq::SliceRandom;
    use rand::SeedableRng;
    let text = std::fs::read_to_string(dir.join(from)).unwrap();
    let mut lines: Vec<&str> = text.lines().collect();
    lines[1..].shuffle(&mut rand_chacha::ChaCha8Rng::seed_from_u64(seed));
    write(dir, to, lines.join("\n") + "\n")
}

/// Three seeds: found in each with its sd within 25 %; the length within 25 % in at least two (its
/// own spread beside the noise and the joint kernel: 18 of seeds 1–20, docs/DESIGN.md; seed 1 reads
/// 7.6 rows, its planted sequence 5.6).
#[test]
fn planted_drift_is_found_with_its_size_and_length_and_not_in_shuffled_rows() {
    let dir = scratch("drift-planted");
    let mut lengths = Vec::new();
    for seed in [1, 2, 3] {
        let data = walk(&dir, &format!("walk{seed}.csv"), seed, &["drift:sd=0.03,length=5"]);
        let d = drift_of(&dir, &data);
        assert_eq!(d["detected"], true, "seed {seed}: {d}");
        let sd = d["sd"].as_f64().unwrap();
        assert!((sd / 0.03 - 1.0).abs() <= 0.25, "seed {seed}: sd {sd} for 0.03: {d}");
        assert!(d["log_likelihood_ratio"].as_f64().unwrap() > d["threshold"].as_f64().unwrap(), "seed {seed}: {d}");
        lengths.push(d["length"].as_f64().unwrap());
    }
    let within = lengths.iter().filter(|l| (*l / 5.0 - 1.0).abs() <= 0.25).count();
    assert!(within >= 2, "lengths {lengths:?} for 5");
    // The same rows in another order: what followed the row index is now white noise.
    let mixed = shuffled(&dir, "walk1.csv", "shuffled.csv", 7);
    let d = drift_of(&dir, &mixed);
    assert_eq!(d["detected"], false, "{d}");
}

/// No drift planted, along the same walk (consecutive poses close in joint space, their residuals
/// correlated through the configuration: the built-in arm's gravity compliance): none reported.
#[test]
fn a_walk_without_drift_reports_none() {
    let dir = scratch("drift-none");
    for seed in [1, 2] {
        let data = walk(&dir, &format!("walk{seed}.csv"), seed, &[]);
        let d = drift_of(&dir, &data);
        assert_eq!(d["detected"], false, "seed {seed}: {d}");
        assert_eq!(d["tested"], true, "seed {seed}: {d}");
    }
}

/// The UR5 campaign in its measured order (issue 49: lag-1 residual correlation 0.47; the prototype
/// `order.py`'s time term 0.038 mm over ≈ 4 poses with a squared-exponential form).
#[test]
fn the_ur5_campaign_drifts() {
    let dir = scratch("drift-ur5");
    let data = ur5_dir().join("train.csv");
    let d = drift_of(&dir, data.to_str().unwrap());
    assert_eq!(d["detected"], true, "{d}");
    let (sd, length) = (d["sd"].as_f64().unwrap(), d["length"].as_f64().unwrap());
    assert!((0.02..0.06).contains(&sd) && (2.0..10.0).contains(&length), "{d}");
}

/// The order must not fool the fit (issue 49 Done when): what `cbd fit` writes from the drifting
/// walk in its measured order is, on 1000 fresh poses, within 2 % of what it writes from the same
/// rows shuffled — a prior that read the drift as a narrow joint kernel would fit the two apart.
#[test]
fn the_fit_from_rows_in_measured_order_predicts_as_well_as_from_the_same_rows_shuffled() {
    let dir = scratch("drift-order-fit");
    let model = examples().join("ur5").join("simulated-six.toml");
    let model = model.to_str().unwrap();
    let data = walk(&dir, "walk.csv", 1, &["drift:sd=0.03,length=5"]);
    let mixed = shuffled(&dir, &data, "shuffled.csv", 7);
    let fresh = ["simulate", "--robot", "six", "--sampling", "uniform", "--count", "1000", "--noise", "0", "--seed", "99"];
    succeeds(&cbd(&dir, &[&fresh[..], &["--out", "fresh.csv"]].concat()));
    let mut means = Vec::new();
    for rows in [&data, &mixed] {
        succeeds(&cbd(&dir, &["fit", "--model", model, "--data", rows, "--out", "m.blob"]));
        succeeds(&cbd(&dir, &["eval", "--model", model, "--blob", "m.blob", "--data", "fresh.csv", "--json", "e.json"]));
        means.push(json(&dir.join("e.json"))["calibrated"]["mean"].as_f64().unwrap());
    }
    assert!((means[0] / means[1] - 1.0).abs() <= 0.02, "measured order {} against shuffled {} on fresh poses", means[0], means[1]);
}

#[test]
fn bad_walks_and_drift_specs_are_refused() {
    let dir = scratch("drift-errors");
    let simulate = |extra: &[&str]| {
        let mut args = vec!["simulate", "--robot", "six", "--count", "50", "--out", "x.csv"];
        args.extend(extra);
        cbd(&dir, &args)
    };
    fails_with(&simulate(&["--sampling", "walk"]), &["--sampling walk needs --step"]);
    fails_with(&simulate(&["--sampling", "walk", "--step", "0"]), &["--step must be"]);
    fails_with(&simulate(&["--sampling", "walk", "--step", "nan"]), &["--step must be"]);
    fails_with(&simulate(&["--sampling", "uniform", "--step", "0.1"]), &["--step is for --sampling walk"]);
    let walk = ["--sampling", "walk", "--step", "0.1"];
    for (spec, needle) in [
        ("drift:sd=0.03,length=5,lenght=4", "unknown key `lenght`"),
        ("drift:sd=0.03,sd=0.02,length=5", "sd= is given twice"),
        ("drift:sd=0.03", "missing length="),
        ("drift:sd=-1,length=5", "sd = -1 must not be negative"),
        ("drift:sd=0.03,length=0", "length = 0 must be positive"),
        ("thermal:dx=1,dq=2", "unknown key `dq`"),
    ] {
        let mut args = walk.to_vec();
        args.extend(["--effect", spec]);
        fails_with(&simulate(&args), &[needle]);
    }
    // The RR arm walks too, in [0, 2π] per joint.
    let out = cbd(
        &dir,
        &["simulate", "--sampling", "walk", "--step", "0.05", "--count", "20", "--effect", "drift:sd=0.01,length=3", "--out", "rr.csv"],
    );
    succeeds(&out);
    let text = std::fs::read_to_string(dir.join("rr.csv")).unwrap();
    assert_eq!(text.lines().count(), 21);
    for line in text.lines().skip(1) {
        let q: Vec<f64> = line.split(',').take(2).map(|v| v.parse().unwrap()).collect();
        assert!(q.iter().all(|v| (0.0..=2.0 * std::f64::consts::PI).contains(v)), "{line}");
    }
}

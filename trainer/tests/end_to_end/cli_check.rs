//! `cbd check` (issue 50 items 1 and 2) through the real binary, on the simulated six-joint arm:
//! the calibration holds on fresh poses of the same arm (exit 0), a joint's zero moved is "changed"
//! (exit 3), a tracker set up anew holds with --register, bad input is one `error:` line naming
//! the file (exit 1), and the same inputs give the same JSON.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::OnceLock;

use crate::cli_support;

const CBD: &str = env!("CARGO_BIN_EXE_cbd");

fn model() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../examples/ur5/simulated-six.toml")
}

fn scratch(name: &str) -> PathBuf {
    cli_support::scratch(&format!("check-{name}"))
}

fn cbd(dir: &Path, args: &[&str]) -> Output {
    Command::new(CBD).args(args).current_dir(dir).output().expect("run cbd")
}

fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

/// 150 calibration poses (noise 0.02 mm) of the simulated arm and the blob `cbd fit` writes.
fn fixture() -> &'static PathBuf {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let dir = scratch("fixture");
        let m = model();
        let m = m.to_str().unwrap();
        let out = cbd(
            &dir,
            &[
                "simulate",
                "--robot",
                "six",
                "--sampling",
                "uniform",
                "--count",
                "150",
                "--noise",
                "0.02",
                "--seed",
                "1",
                "--out",
                "cal.csv",
            ],
        );
        assert!(out.status.success(), "{}", text(&out.stderr));
        let out = cbd(&dir, &["fit", "--model", m, "--data", "cal.csv", "--out", "arm.blob", "--quiet"]);
        assert!(out.status.success(), "{}", text(&out.stderr));
        dir
    })
}

/// 20 fresh poses of the same arm (seed `seed`), with extra simulate flags.
fn fresh(dir: &Path, name: &str, seed: u64, extra: &[&str]) {
    let seed = seed.to_string();
    let mut args =
        vec!["simulate", "--robot", "six", "--sampling", "uniform", "--count", "20", "--noise", "0.02", "--seed", &seed, "--out", name];
    args.extend_from_slice(extra);
    let out = cbd(dir, &args);
    assert!(out.status.success(), "{}", text(&out.stderr));
}

fn check(dir: &Path, data: &str, extra: &[&str]) -> Output {
    let blob = fixture().join("arm.blob");
    let m = model();
    let mut args = vec!["check", "--model", m.to_str().unwrap(), "--blob", blob.to_str().unwrap(), "--data", data];
    args.extend_from_slice(extra);
    cbd(dir, &args)
}

fn json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

/// Exit code 1, one `error:` line holding every needle, no panic.
#[track_caller]
fn fails_with(out: &Output, needles: &[&str]) {
    let err = text(&out.stderr);
    assert!(!err.contains("panicked"), "panic:\n{err}");
    assert_eq!(out.status.code(), Some(1), "stderr:\n{err}");
    let line = err.lines().find(|l| l.starts_with("error: ")).unwrap_or_else(|| panic!("no error line:\n{err}"));
    for n in needles {
        assert!(line.contains(n), "{line:?} lacks {n:?}");
    }
}

#[test]
fn fresh_poses_of_the_same_arm_hold_and_the_json_says_so() {
    let dir = scratch("holds");
    fresh(&dir, "fresh.csv", 1001, &[]);
    let out = check(&dir, "fresh.csv", &["--json", "c.json", "--log", "checks.jsonl"]);
    let stdout = text(&out.stdout);
    assert_eq!(out.status.code(), Some(0), "{stdout}\n{}", text(&out.stderr));
    assert!(stdout.contains("holds (p = "), "{stdout}");
    assert!(stdout.contains("noise floor"), "{stdout}");
    let v = json(&dir.join("c.json"));
    assert_eq!(v["verdict"], "holds");
    assert_eq!(v["dof"], 60);
    assert_eq!(v["alpha"], 0.01);
    assert_eq!(v["changes"], serde_json::json!([]));
    assert!(v["frame"].is_null());
    let p = v["p_value"].as_f64().unwrap();
    assert!(p >= 0.01 && p <= 1.0, "p = {p}");
    // Determinism: the same inputs, the same JSON, bit for bit.
    let again = check(&dir, "fresh.csv", &["--json", "c2.json", "--log", "checks.jsonl"]);
    assert_eq!(again.status.code(), Some(0));
    assert_eq!(std::fs::read(dir.join("c.json")).unwrap(), std::fs::read(dir.join("c2.json")).unwrap());
    // --log: one JSON line per check.
    let log = std::fs::read_to_string(dir.join("checks.jsonl")).unwrap();
    let lines: Vec<serde_json::Value> = log.lines().map(|l| serde_json::from_str(l).unwrap()).collect();
    assert_eq!(lines.len(), 2);
    assert_eq!(lines[1]["verdict"], "holds");
    assert_eq!(lines[1]["p_value"], v["p_value"]);
    assert!(lines[1]["time"].as_str().unwrap().ends_with('Z'));
}

/// Joint 2's zero moved by 0.01° (0.14 mm at the UR5's reach, seven times σ): the encoder reads
/// q − δ at the same arm pose. Exit 3, "changed", also with --register (a joint zero is not a frame).
#[test]
fn a_moved_joint_zero_is_changed_with_exit_code_3() {
    let dir = scratch("changed");
    fresh(&dir, "raw.csv", 1002, &[]);
    let raw = std::fs::read_to_string(dir.join("raw.csv")).unwrap();
    let mut shifted = String::new();
    for (i, line) in raw.lines().enumerate() {
        if i == 0 {
            shifted.push_str(line);
        } else {
            let mut f: Vec<String> = line.split(',').map(str::to_owned).collect();
            f[1] = format!("{}", f[1].parse::<f64>().unwrap() - 0.01);
            shifted.push_str(&f.join(","));
        }
        shifted.push('\n');
    }
    std::fs::write(dir.join("moved.csv"), shifted).unwrap();
    for extra in [&[][..], &["--register"][..]] {
        let mut args = vec!["--json", "c.json"];
        args.extend_from_slice(extra);
        let out = check(&dir, "moved.csv", &args);
        let stdout = text(&out.stdout);
        assert_eq!(out.status.code(), Some(3), "{extra:?}\n{stdout}\n{}", text(&out.stderr));
        assert!(stdout.contains("changed (p = "), "{stdout}");
        let v = json(&dir.join("c.json"));
        assert_eq!(v["verdict"], "changed");
        assert!(v["p_value"].as_f64().unwrap() < 1e-6, "{v}");
    }
}

/// The tracker set up 1 m and 30° away: without --register a change, with it the calibration
/// holds, the frame is reported and the test loses its 6 degrees of freedom.
#[test]
fn a_tracker_set_up_anew_holds_when_registered() {
    let dir = scratch("tracker");
    fresh(&dir, "moved.csv", 1003, &["--tracker-frame", "577.35,577.35,577.35;1,2,3,30"]);
    let out = check(&dir, "moved.csv", &[]);
    assert_eq!(out.status.code(), Some(3), "{}", text(&out.stdout));
    let out = check(&dir, "moved.csv", &["--register", "--json", "c.json"]);
    let stdout = text(&out.stdout);
    assert_eq!(out.status.code(), Some(0), "{stdout}\n{}", text(&out.stderr));
    assert!(stdout.contains("frame registered"), "{stdout}");
    let v = json(&dir.join("c.json"));
    assert_eq!(v["dof"], 54);
    let angle = v["frame"]["angle_deg"].as_f64().unwrap();
    assert!((angle - 30.0).abs() < 0.01, "{angle}");
}

#[test]
fn bad_input_is_one_line_naming_the_file() {
    let dir = scratch("bad");
    fresh(&dir, "fresh.csv", 1004, &[]);
    for alpha in ["--alpha=0", "--alpha=1", "--alpha=-0.5", "--alpha=nan"] {
        fails_with(&check(&dir, "fresh.csv", &[alpha]), &["--alpha"]);
    }
    // Other columns than the model's: a planar arm's file.
    let out = cbd(&dir, &["simulate", "--grid", "3", "--out", "rr.csv"]);
    assert!(out.status.success());
    fails_with(&check(&dir, "rr.csv", &[]), &["rr.csv"]);
    // Fewer rows than the frame's 6 degrees of freedom (a model file that reads 1 row and up).
    let text_model = std::fs::read_to_string(model()).unwrap().replace("min_rows = 10", "min_rows = 1");
    std::fs::write(dir.join("six.toml"), text_model).unwrap();
    let all = std::fs::read_to_string(dir.join("fresh.csv")).unwrap();
    std::fs::write(dir.join("four.csv"), all.lines().take(5).collect::<Vec<_>>().join("\n") + "\n").unwrap();
    let blob = fixture().join("arm.blob");
    let out = cbd(&dir, &["check", "--model", "six.toml", "--blob", blob.to_str().unwrap(), "--data", "four.csv", "--register"]);
    fails_with(&out, &["four.csv", "4 fresh rows", "6"]);
    // A blob without σ (format 6 or older): refused, saying so.
    let bytes = std::fs::read(&blob).unwrap();
    let mut old = cbd_protocol::decode(&bytes).unwrap();
    old.noise_sigma = None;
    old.drift = None;
    old.configuration_kernel = None;
    std::fs::write(dir.join("old.blob"), cbd_protocol::encode_to_vec(&old).unwrap()).unwrap();
    let m = model();
    let out = cbd(&dir, &["check", "--model", m.to_str().unwrap(), "--blob", "old.blob", "--data", "fresh.csv"]);
    fails_with(&out, &["old.blob", "no noise σ"]);
}

/// The paper's noise-free RR grid: the blob's σ (2.6e-8) is below what double precision resolves in
/// the predictive covariance. Refused naming the blob and what to do (--sigma); with the
/// instrument's noise given, the same check runs and holds.
#[test]
fn a_noise_free_blob_is_refused_saying_what_to_do() {
    let dir = scratch("noise-free");
    for args in [
        &["simulate", "--grid", "16", "--out", "grid.csv"][..],
        &["simulate", "--sampling", "uniform", "--count", "50", "--seed", "2", "--out", "fresh.csv"],
        &["fit", "--data", "grid.csv", "--out", "exact.blob", "--quiet"],
    ] {
        let out = cbd(&dir, args);
        assert!(out.status.success(), "{args:?}: {}", text(&out.stderr));
    }
    fails_with(&cbd(&dir, &["check", "--blob", "exact.blob", "--data", "fresh.csv"]), &["exact.blob", "not positive definite", "--sigma"]);
    let out = cbd(&dir, &["fit", "--data", "grid.csv", "--out", "given.blob", "--quiet", "--sigma", "1e-4"]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let out = cbd(&dir, &["check", "--blob", "given.blob", "--data", "fresh.csv"]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
}

/// Naming the change (issue 50 item 3): one planted change of a detectable size per set of 20
/// fresh poses (`cbd simulate --effect`, the same arm); the check says "changed", the first named
/// change is the planted one by its `--effect` spelling, its size within 4 standard errors of the
/// truth (a shift: its length), and what is left after it is no longer a change at α = 0.01. With
/// --register, base_shift is not offered (the frame holds it) and a joint zero is still named.
#[test]
fn a_planted_change_is_named_with_its_size() {
    let dir = scratch("named");
    let cases: [(&str, &str, f64, &[&str]); 6] = [
        ("joint_zero:joint=2,offset=1e-4", "joint_zero:joint=2", 1e-4, &[]),
        ("base_shift:dx=0.1", "base_shift", 0.1, &[]),
        ("tool_shift:dz=0.1", "tool_shift", 0.1, &[]),
        ("link_length:link=3,delta=0.1", "link_length:link=3", 0.1, &[]),
        ("length_scale:scale=1.0002", "length_scale", 2e-4, &[]),
        ("joint_zero:joint=3,offset=1e-4", "joint_zero:joint=3", 1e-4, &["--register"]),
    ];
    for (i, (plant, spelling, truth, extra)) in cases.into_iter().enumerate() {
        let name = format!("changed{i}.csv");
        fresh(&dir, &name, 1100 + i as u64, &["--effect", plant]);
        let mut args = vec!["--json", "c.json"];
        args.extend_from_slice(extra);
        let out = check(&dir, &name, &args);
        let stdout = text(&out.stdout);
        assert_eq!(out.status.code(), Some(3), "{plant}\n{stdout}\n{}", text(&out.stderr));
        assert!(stdout.contains("named change") && stdout.contains(spelling), "{plant}\n{stdout}");
        let v = json(&dir.join("c.json"));
        let changes = v["changes"].as_array().unwrap();
        assert!(!changes.is_empty(), "{plant}: {v}");
        let first = &changes[0];
        assert_eq!(first["effect"], spelling, "{plant}: {v}");
        let (size, se) = (first["size"].as_f64().unwrap(), first["se"].as_f64().unwrap());
        assert!(se > 0.0 && (size - truth).abs() < 4.0 * se, "{plant}: size {size} ± {se}, truth {truth}");
        let after = v["after_change"]["p_value"].as_f64().unwrap();
        assert!(after >= 0.01, "{plant}: p after the named change {after}\n{stdout}");
        if !extra.is_empty() {
            assert!(stdout.contains("not offered: base_shift"), "{stdout}");
            assert_eq!(v["after_change"]["not_offered"][0]["effect"], "base_shift");
        }
    }
    // Nothing planted: the calibration holds, nothing named.
    fresh(&dir, "same.csv", 1100, &[]);
    let out = check(&dir, "same.csv", &["--json", "c.json"]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stdout));
    let v = json(&dir.join("c.json"));
    assert_eq!(v["changes"], serde_json::json!([]));
    assert!(v["after_change"].is_null());
}

/// History (issue 50 item 6): two checks appended to one `--log` (one holds, one changed), then
/// `cbd report --checks` draws both: the page holds the trend figure and a table row per check,
/// with the named change; a malformed line is an error naming the log and the line.
#[test]
fn report_draws_the_history_of_the_check_log() {
    let dir = scratch("history");
    fresh(&dir, "same.csv", 1201, &[]);
    fresh(&dir, "moved.csv", 1202, &["--effect", "joint_zero:joint=2,offset=1e-4"]);
    assert_eq!(check(&dir, "same.csv", &["--log", "checks.jsonl"]).status.code(), Some(0));
    assert_eq!(check(&dir, "moved.csv", &["--log", "checks.jsonl"]).status.code(), Some(3));
    let log = std::fs::read_to_string(dir.join("checks.jsonl")).unwrap();
    let lines: Vec<serde_json::Value> = log.lines().map(|l| serde_json::from_str(l).unwrap()).collect();
    assert_eq!(lines.len(), 2);
    assert!(lines[0]["floor"].as_f64().unwrap() > 0.0 && lines[0]["floor_limit"].as_f64() > lines[0]["floor"].as_f64());
    assert_eq!(lines[1]["changes"][0]["effect"], "joint_zero:joint=2");
    let out = cbd(&dir, &["report", "--checks", "checks.jsonl", "--out", "history.html"]);
    let stdout = text(&out.stdout);
    assert!(out.status.success(), "{stdout}\n{}", text(&out.stderr));
    assert!(stdout.contains("2 checks drawn"), "{stdout}");
    let page = std::fs::read_to_string(dir.join("history.html")).unwrap();
    assert!(page.contains("<svg") && page.contains("Checks of the calibration over time"), "no figure");
    assert_eq!(page.matches("<tr><td class=num>").count(), 2, "one row per check");
    for needle in ["same.csv", "moved.csv", "holds", "changed", "joint_zero:joint=2", "1 of 2 checks changed", "mean error (mm)"] {
        assert!(page.contains(needle), "page lacks {needle:?}");
    }
    std::fs::write(dir.join("bad.jsonl"), format!("{}\n{{\"time\": 3}}\n", log.lines().next().unwrap())).unwrap();
    fails_with(&cbd(&dir, &["report", "--checks", "bad.jsonl", "--out", "bad.html"]), &["bad.jsonl:2:", "time"]);
    // One of --json and --checks is needed.
    let out = cbd(&dir, &["report", "--out", "x.html"]);
    assert!(!out.status.success() && text(&out.stderr).contains("--checks"), "{}", text(&out.stderr));
}

/// `cbd plan --check N --blob B` (issue 50 item 5): 20 poses within the model file's joint limits
/// as `cbd plan` writes them, and for every kind of change the check names the smallest it detects
/// at α = 0.01 with 90 % power, with 20 random and 20 planned poses. The planned ones are never
/// worse than random in the median over the kinds; the joint zero the other tests plant (1e-4 rad)
/// is above what they detect; a change of the planned size at the planned poses is "changed".
#[test]
fn plan_check_finds_poses_and_the_smallest_detectable_changes() {
    let dir = scratch("plan");
    let blob = fixture().join("arm.blob");
    let m = model();
    let args = [
        "plan",
        "--model",
        m.to_str().unwrap(),
        "--check",
        "20",
        "--blob",
        blob.to_str().unwrap(),
        "--out",
        "poses.csv",
        "--json",
        "p.json",
        "--candidates",
        "2000",
    ];
    let out = cbd(&dir, &args);
    let stdout = text(&out.stdout);
    assert!(out.status.success(), "{stdout}\n{}", text(&out.stderr));
    assert!(stdout.contains("smallest change the check detects at alpha = 0.01 with 90 % power (60 degrees of freedom"), "{stdout}");
    let csv = std::fs::read_to_string(dir.join("poses.csv")).unwrap();
    let mut lines = csv.lines();
    assert_eq!(lines.next().unwrap(), "q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg");
    let rows: Vec<Vec<f64>> = lines.map(|l| l.split(',').map(|v| v.parse().unwrap()).collect()).collect();
    assert_eq!(rows.len(), 20);
    assert!(rows.iter().flatten().all(|v| v.abs() <= 360.0));
    let v = json(&dir.join("p.json"));
    assert_eq!(v["dof"], 60);
    let sizes = v["sizes"].as_array().unwrap();
    assert!(sizes.len() >= 20, "{v}");
    let mut ratios: Vec<f64> = Vec::new();
    for s in sizes {
        let (random, planned) = (s["random"].as_f64().unwrap(), s["planned"].as_f64().unwrap());
        assert!(random > 0.0 && planned > 0.0 && random.is_finite() && planned.is_finite(), "{s}");
        ratios.push(random / planned);
    }
    ratios.sort_by(f64::total_cmp);
    assert!(ratios[ratios.len() / 2] >= 1.0 && ratios[0] > 0.9, "random / planned: {ratios:?}");
    let zero2 = sizes.iter().find(|s| s["effect"] == "joint_zero:joint=2").unwrap();
    let planned = zero2["planned"].as_f64().unwrap();
    assert!(planned < 1e-4 && planned > 1e-5, "{zero2}");
    // Twice the planned size at the planned poses: changed (power far above 0.9).
    let plant = format!("joint_zero:joint=2,offset={:e}", 2.0 * planned);
    let out = cbd(
        &dir,
        &[
            "simulate",
            "--robot",
            "six",
            "--poses",
            "poses.csv",
            "--noise",
            "0.02",
            "--seed",
            "1301",
            "--effect",
            &plant,
            "--out",
            "moved.csv",
        ],
    );
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert_eq!(check(&dir, "moved.csv", &[]).status.code(), Some(3));
    // Planned for a registered check: 6 degrees of freedom fewer, no base shift offered, and a
    // joint zero (which the frame cannot take up) still detected at about the same size.
    let mut registered = args.to_vec();
    registered.extend(["--register"]);
    registered[8] = "reg.csv";
    registered[10] = "reg.json";
    let out = cbd(&dir, &registered);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let r = json(&dir.join("reg.json"));
    assert_eq!(r["dof"], 54);
    let effects: Vec<&str> = r["sizes"].as_array().unwrap().iter().map(|s| s["effect"].as_str().unwrap()).collect();
    assert!(!effects.contains(&"base_shift") && effects.contains(&"tool_shift"), "{effects:?}");
    // Joint 1's zero turns the arm about the base's axis, as the frame does: the registered check
    // cannot see it, and the plan says so instead of printing a size.
    assert_eq!(r["taken_up_by_the_frame"], serde_json::json!(["joint_zero:joint=1"]), "{r}");
    for s in r["sizes"].as_array().unwrap() {
        assert!(s["random"].as_f64().is_some_and(f64::is_finite) && s["planned"].as_f64().is_some_and(f64::is_finite), "{s}");
    }
    let zero2r = r["sizes"].as_array().unwrap().iter().find(|s| s["effect"] == "joint_zero:joint=2").unwrap();
    let (free, framed) = (zero2["random"].as_f64().unwrap(), zero2r["random"].as_f64().unwrap());
    assert!(framed >= free * 0.99 && framed < 3.0 * free, "joint 2 zero, random poses: {free} free, {framed} registered");
    let out = cbd(
        &dir,
        &["plan", "--model", m.to_str().unwrap(), "--check", "2", "--blob", blob.to_str().unwrap(), "--out", "y.csv", "--register"],
    );
    assert_eq!(out.status.code(), Some(1), "{}", text(&out.stderr));
    assert!(text(&out.stderr).contains("at least 3"), "{}", text(&out.stderr));
    // --check needs --blob.
    let out = cbd(&dir, &["plan", "--model", m.to_str().unwrap(), "--check", "20", "--out", "x.csv"]);
    assert!(!out.status.success() && text(&out.stderr).contains("--blob"), "{}", text(&out.stderr));
}

/// `--update` (issue 50 item 4): a planted joint zero is refitted into a new blob that records its
/// parent's SHA-256; the new blob is nearer the changed arm than its parent on poses neither saw,
/// and the check of it holds. Where the calibration holds nothing is written; `--update` without
/// `--out` is refused.
#[test]
fn update_refits_the_named_change_into_a_blob_that_names_its_parent() {
    use sha2::Digest as _;
    let dir = scratch("update");
    let plant = "joint_zero:joint=2,offset=1e-4";
    fresh(&dir, "changed.csv", 1201, &["--effect", plant]);
    fresh(&dir, "test.csv", 1202, &["--effect", plant]);
    let out = check(&dir, "changed.csv", &["--json", "c.json", "--update", "--out", "new.blob"]);
    let stdout = text(&out.stdout);
    assert_eq!(out.status.code(), Some(3), "{stdout}\n{}", text(&out.stderr));
    assert!(stdout.contains("updated: joint_zero:joint=2 by "), "{stdout}");
    let v = json(&dir.join("c.json"));
    let u = &v["update"];
    assert_eq!(u["groups"][0]["effect"], "joint_zero:joint=2", "{v}");
    let refitted = u["groups"][0]["values"][0].as_f64().unwrap();
    assert!((refitted - 1e-4).abs() < 3e-5, "{refitted}");
    let (before, after) = (u["before"].as_f64().unwrap(), u["after"].as_f64().unwrap());
    assert!(after < 0.7 * before, "held out: {before} → {after}");
    let parent = std::fs::read(fixture().join("arm.blob")).unwrap();
    let new = std::fs::read(dir.join("new.blob")).unwrap();
    let hash: [u8; 32] = sha2::Sha256::digest(&parent).into();
    let hex: String = hash.iter().map(|b| format!("{b:02x}")).collect();
    assert_eq!(u["parent_sha256"], hex.as_str());
    let model = cbd_protocol::decode(&new).unwrap();
    assert_eq!(model.provenance.and_then(|p| p.parent), Some(hash));
    // On poses neither blob saw, the updated blob is nearer the changed arm, and it holds there.
    let m = model_path();
    let eval = |blob: &Path| {
        let out = cbd(&dir, &["eval", "--model", &m, "--blob", blob.to_str().unwrap(), "--data", "test.csv", "--json", "e.json"]);
        assert!(out.status.success(), "{}", text(&out.stderr));
        json(&dir.join("e.json"))["calibrated"]["mean"].as_f64().unwrap()
    };
    let (old, updated) = (eval(&fixture().join("arm.blob")), eval(&dir.join("new.blob")));
    assert!(updated < 0.8 * old, "test poses: parent {old}, updated {updated}");
    let out = cbd(&dir, &["check", "--model", &m, "--blob", "new.blob", "--data", "test.csv"]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stdout));
    // The same arm: the calibration holds, nothing is written.
    fresh(&dir, "same.csv", 1203, &[]);
    let out = check(&dir, "same.csv", &["--update", "--out", "unwritten.blob"]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stdout));
    assert!(text(&out.stdout).contains("the calibration holds; unwritten.blob is not written"), "{}", text(&out.stdout));
    assert!(!dir.join("unwritten.blob").exists());
    let out = check(&dir, "changed.csv", &["--update"]);
    assert_eq!(out.status.code(), Some(2), "{}", text(&out.stderr));
    assert!(text(&out.stderr).contains("--out"), "{}", text(&out.stderr));
}

fn model_path() -> String {
    model().to_str().unwrap().to_string()
}

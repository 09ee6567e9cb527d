//! Issue 51 ("Reliability V") through the real binary. Class 2: a command that fails leaves every
//! output path it was given as it found it — each pre-existing output byte-identical, no new file
//! or directory left behind — whichever output flag and however late the failure.

use crate::cli_support;

use cli_support::*;
use std::collections::BTreeMap;
use std::path::Path;

/// Every file under `dir` (recursively) with its bytes, and every directory, by relative path.
fn tree(dir: &Path) -> BTreeMap<String, Option<Vec<u8>>> {
    fn walk(root: &Path, at: &Path, into: &mut BTreeMap<String, Option<Vec<u8>>>) {
        for entry in std::fs::read_dir(at).unwrap() {
            let path = entry.unwrap().path();
            let name = path.strip_prefix(root).unwrap().to_string_lossy().into_owned();
            if path.is_dir() {
                into.insert(name, None);
                walk(root, &path, into);
            } else {
                into.insert(name, Some(std::fs::read(&path).unwrap()));
            }
        }
    }
    let mut files = BTreeMap::new();
    walk(dir, dir, &mut files);
    files
}

/// One command that fails after its work: `outputs` are its output files (each given
/// beforehand with a sentinel's bytes), `plots` the figures its `--plots out` directory holds
/// (each given beforehand, the last one blocked by a directory of its name: the late failure).
struct Case {
    what: &'static str,
    args: Vec<String>,
    outputs: &'static [&'static str],
    plots: &'static [&'static str],
}

/// Runs `case` in `dir`; asserts it fails and that the directory is byte-for-byte as before.
#[track_caller]
fn leaves_outputs_alone(dir: &Path, case: &Case) {
    for (k, name) in case.outputs.iter().enumerate() {
        write(dir, name, format!("{} was here before {k}\n", case.what));
    }
    if !case.plots.is_empty() {
        let plots = dir.join("out");
        let _ = std::fs::remove_dir_all(&plots);
        std::fs::create_dir(&plots).unwrap();
        let (blocked, kept) = case.plots.split_last().unwrap();
        for name in kept {
            std::fs::write(plots.join(name), format!("{name} of an earlier run\n")).unwrap();
        }
        std::fs::create_dir(plots.join(blocked)).unwrap();
    }
    let before = tree(dir);
    let args: Vec<&str> = case.args.iter().map(String::as_str).collect();
    let out = cbd(dir, &args);
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(1), "{}: should fail late; stderr:\n{err}", case.what);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(!stdout.contains("written to"), "{}: a line claims a file the failure did not write:\n{stdout}", case.what);
    assert!(!err.contains("panicked"), "{}: {err}", case.what);
    let after = tree(dir);
    for (name, bytes) in &before {
        assert_eq!(after.get(name), Some(bytes), "{}: {name} changed or went; stderr:\n{err}", case.what);
    }
    let new: Vec<&String> = after.keys().filter(|k| !before.contains_key(*k)).collect();
    assert!(new.is_empty(), "{}: left behind {new:?}; stderr:\n{err}", case.what);
}

fn strings(args: &[&str]) -> Vec<String> {
    args.iter().map(|s| s.to_string()).collect()
}

/// Every command with output files and a late failure, each with all its output flags given.
#[test]
fn a_command_that_fails_late_leaves_every_output_byte_identical() {
    let dir = scratch("rel5-outputs");
    write(&dir, "rr.toml", PLANAR_RR_MODEL);
    rr_grid(&dir, "train.csv", 8);
    succeeds(&cbd(&dir, &["simulate", "--sampling", "uniform", "--count", "30", "--seed", "3", "--out", "test.csv"]));
    succeeds(&cbd(&dir, &["fit", "--quiet", "--model", "rr.toml", "--data", "train.csv", "--out", "rr.blob"]));
    let (ur5_data, ur5) = (ur5_head(&dir, "ur5.csv", 300), ur5_model());
    succeeds(&cbd(&dir, &["fit", "--quiet", "--dh-first", "--model", &ur5, "--data", &ur5_data, "--out", "ur5.blob"]));
    let header = std::fs::read_to_string(dir.join(&ur5_data)).unwrap().lines().next().unwrap().to_string();
    write(&dir, "empty.csv", header + "\n");

    let cases = [
        Case {
            what: "eval --json --plots",
            args: strings(&["eval", "--model", "rr.toml", "--blob", "rr.blob", "--data", "test.csv", "--json", "e.json", "--plots", "out"]),
            outputs: &["e.json"],
            plots: &["error_heatmaps.png", "error_heatmaps.svg", "error_histogram.png", "error_histogram.svg"],
        },
        Case {
            what: "compare --json --plots",
            args: strings(&[
                "compare",
                "--quiet",
                "--model",
                "rr.toml",
                "--train",
                "train.csv",
                "--test",
                "test.csv",
                "--json",
                "c.json",
                "--plots",
                "out",
            ]),
            outputs: &["c.json"],
            plots: &["method_comparison.png", "method_comparison.svg"],
        },
        Case {
            what: "diagnose --json --write-model --plots",
            args: strings(&[
                "diagnose",
                "--quiet",
                "--model",
                "rr.toml",
                "--data",
                "train.csv",
                "--test",
                "test.csv",
                "--json",
                "d.json",
                "--write-model",
                "w.toml",
                "--plots",
                "out",
            ]),
            outputs: &["d.json", "w.toml"],
            plots: &["residual_vs_joint.png", "residual_vs_joint.svg"],
        },
        Case {
            what: "demo --out --json --plots",
            args: strings(&[
                "demo",
                "--quiet",
                "--grid",
                "6",
                "--test-points",
                "20",
                "--out",
                "demo.blob",
                "--json",
                "demo.json",
                "--plots",
                "out",
            ]),
            outputs: &["demo.blob", "demo.json"],
            plots: &[
                "convergence.png",
                "convergence.svg",
                "error_heatmaps.png",
                "error_heatmaps.svg",
                "error_histogram.png",
                "error_histogram.svg",
                "workspace_grid.png",
                "workspace_grid.svg",
            ],
        },
        Case {
            // The URDF and the YAML are written, then --data turns out to hold no row.
            what: "export --urdf --ur-kinematics --data (0 rows)",
            args: strings(&[
                "export",
                "--model",
                &ur5,
                "--blob",
                "ur5.blob",
                "--urdf",
                "u.urdf",
                "--ur-kinematics",
                "u.yaml",
                "--data",
                "empty.csv",
            ]),
            outputs: &["u.urdf", "u.yaml"],
            plots: &[],
        },
    ];
    for case in &cases {
        leaves_outputs_alone(&dir, case);
    }
    // The same commands, without the blocker, do write (the cases fail where they are meant to).
    let _ = std::fs::remove_dir_all(dir.join("out"));
    succeeds(&cbd(&dir, &["eval", "--model", "rr.toml", "--blob", "rr.blob", "--data", "test.csv", "--json", "e.json", "--plots", "out"]));
    assert!(json(&dir.join("e.json")).is_object() && dir.join("out/error_histogram.svg").is_file());
}

/// A `--plots` directory that cannot be made or written is refused before any work, naming the
/// flag; the other outputs are untouched.
#[test]
fn an_unwritable_plots_directory_is_refused_before_the_work() {
    let dir = scratch("rel5-plots-dir");
    write(&dir, "rr.toml", PLANAR_RR_MODEL);
    rr_grid(&dir, "train.csv", 6);
    succeeds(&cbd(&dir, &["fit", "--quiet", "--model", "rr.toml", "--data", "train.csv", "--out", "rr.blob"]));
    write(&dir, "e.json", "before\n");
    write(&dir, "file.txt", "a file\n");
    for plots in ["file.txt", "file.txt/figures", "file.txt/a/b"] {
        let err = fails_with(
            &cbd(&dir, &["eval", "--model", "rr.toml", "--blob", "rr.blob", "--data", "train.csv", "--json", "e.json", "--plots", plots]),
            &["--plots", plots],
        );
        assert!(!err.contains("mean error"), "the work ran first:\n{err}");
        assert_eq!(std::fs::read_to_string(dir.join("e.json")).unwrap(), "before\n");
    }
}

/// The UR5 example's chain in metres, named `name` (TOML basic string, escapes allowed), its base
/// `base` (a TOML inline table), the data in millimetres as the example's.
fn ur5_in_metres(base: &str, name: &str) -> String {
    format!(
        "name = \"{name}\"\nlength_unit = \"m\"\nangle_unit = \"deg\"\n[chain]\nconvention = \"standard\"\njoints = [\n  {{ a = 0, alpha = 90, d = 0.089159, theta_offset = 0 }},\n  {{ a = -0.425, alpha = 0, d = 0, theta_offset = 0 }},\n  {{ a = -0.39225, alpha = 0, d = 0, theta_offset = 0 }},\n  {{ a = 0, alpha = 90, d = 0.10915, theta_offset = 0 }},\n  {{ a = 0, alpha = -90, d = 0.09465, theta_offset = 0 }},\n  {{ a = 0, alpha = 0, d = 0.0823, theta_offset = 0 }},\n]\nbase = {base}\ntool = {{ translation = [0, 0, 0.031] }}\n[measurements]\njoints = [\"q1_deg\", \"q2_deg\", \"q3_deg\", \"q4_deg\", \"q5_deg\", \"q6_deg\"]\npositions = [\"x_mm\", \"y_mm\", \"z_mm\"]\nangle_unit = \"deg\"\nlength_unit = \"mm\"\nmin_rows = 10\n"
    )
}

/// The `<joint>` origins (metres) of a URDF read back by urdf-rs, by joint name.
fn origins(urdf: &str) -> Vec<(String, [f64; 3])> {
    urdf_rs::read_from_string(urdf).unwrap().joints.iter().map(|j| (j.name.clone(), j.origin.xyz.0)).collect()
}

/// Issue 51 class 1 through `cbd export`: a metre model whose name and file names hold entities,
/// quotes, `---`, a newline and non-ASCII writes a URDF and a YAML that parse back (the name as
/// written), and its geometry-alone line is readable; a model whose base is registered on a
/// tracker's data exports that frame with the links where the nominal puts them in it (no link
/// slid metres along its axis), the TCP the tool's 31 mm.
#[test]
fn export_writes_well_formed_files_in_the_right_frame() {
    let dir = scratch("rel5-export");
    let name = "UR5 &amp; <\\\"ü\\\"> --- x\\nsecond";
    let model = write(&dir, "ur5 --- m.toml", ur5_in_metres("{ translation = [0, 0, 0], rpy = [0, 0, 0] }", name));
    let data = ur5_head(&dir, "train.csv", 300);
    let blob = "fit -- \"ü\" &amp; \n---.blob";
    succeeds(&cbd(&dir, &["fit", "--quiet", "--dh-first", "--model", &model, "--data", &data, "--out", blob]));
    let test = ur5_dir().join("test.csv");
    let out = cbd(
        &dir,
        &["export", "--model", &model, "--blob", blob, "--urdf", "m.urdf", "--ur-kinematics", "m.yaml", "--data", test.to_str().unwrap()],
    );
    succeeds(&out);
    let stdout = String::from_utf8_lossy(&out.stdout);
    let line = stdout.lines().find(|l| l.contains("URDF alone")).expect("the geometry-alone line");
    assert!(!line.contains(" 0.000 m") && line.contains("e-"), "{line}");
    let urdf = std::fs::read_to_string(dir.join("m.urdf")).unwrap();
    for event in xml::reader::EventReader::from_str(&urdf) {
        event.unwrap_or_else(|e| panic!("{e}\n{urdf}"));
    }
    assert_eq!(urdf_rs::read_from_string(&urdf).unwrap().name, "UR5 &amp; <\"ü\"> --- x\nsecond");
    let yaml = std::fs::read_to_string(dir.join("m.yaml")).unwrap();
    let docs = yaml_rust2::YamlLoader::load_from_str(&yaml).unwrap_or_else(|e| panic!("{e}\n{yaml}"));
    assert_eq!(docs.len(), 1);
    assert_eq!(docs[0].as_hash().unwrap().len(), 1, "{yaml}");
    assert!(docs[0]["kinematics"]["shoulder"]["z"].as_f64().is_some_and(|z| (z - 0.089159).abs() < 0.01), "{yaml}");
    // The URDF imports as a model file's chain (cbd's own reader) too.
    write(
        &dir,
        "back.toml",
        "length_unit = \"m\"\nangle_unit = \"rad\"\n[urdf]\npath = \"m.urdf\"\nbase_link = \"base_link\"\ntip_link = \"tool0\"\n",
    );
    let back = cbd_trainer::data::model_file::load_model_file(dir.join("back.toml")).unwrap();
    assert_eq!(back.joint_names.len(), 6);

    // A base registered on a tracker's data (3 m away, turned 30°).
    let tracked = "tracker.csv";
    succeeds(&cbd(
        &dir,
        &[
            "simulate",
            "--robot",
            "six",
            "--sampling",
            "uniform",
            "--count",
            "200",
            "--seed",
            "2",
            "--tracker-frame",
            "3000,-2000,1000;1,1,0,30",
            "--out",
            tracked,
        ],
    ));
    let registered = write(
        &dir,
        "registered.toml",
        std::fs::read_to_string(ur5_model())
            .unwrap()
            .replace("base = { translation = [0, 0, 0], rpy = [0, 0, 0] }", "base = { register = true }"),
    );
    succeeds(&cbd(&dir, &["fit", "--quiet", "--dh-first", "--model", &registered, "--data", tracked, "--out", "r.blob"]));
    let out = cbd(
        &dir,
        &["export", "--model", &registered, "--blob", "r.blob", "--urdf", "r.urdf", "--ur-kinematics", "r.yaml", "--data", tracked],
    );
    succeeds(&out);
    let stdout = String::from_utf8_lossy(&out.stdout);
    let tcp = stdout.lines().find(|l| l.contains("TCP in tool0")).unwrap();
    let z: f64 = tcp.split("xyz [").nth(1).unwrap().split(']').next().unwrap().split(", ").nth(2).unwrap().parse().unwrap();
    assert!((z - 0.031).abs() < 0.002, "{tcp}");
    let origins = origins(&std::fs::read_to_string(dir.join("r.urdf")).unwrap());
    let base = origins.iter().find(|(n, _)| n == "base_joint").unwrap().1;
    assert!((base[0] - 3.0).abs() < 0.01 && (base[1] + 2.0).abs() < 0.01, "the registered frame: {base:?}");
    for (joint, xyz) in origins.iter().filter(|(n, _)| n != "base_joint") {
        let length = xyz.iter().map(|v| v * v).sum::<f64>().sqrt();
        assert!(length < 0.5, "{joint} slid {length} m: {origins:?}");
    }
}

/// Issue 51 classes 3 and 6: one bound for σ wherever it is read (flag, blob), refused with the
/// field and the value as written; values near a bound echoed exactly; a ratio far from 1 printed
/// readably; "not finite" only for what is not; a header's invisible character named.
#[test]
fn numbers_are_bounded_once_and_echoed_as_written() {
    let dir = scratch("rel5-numbers");
    write(&dir, "rr.toml", PLANAR_RR_MODEL);
    rr_grid(&dir, "train.csv", 8);
    // σ from a blob: 1e300 and a subnormal refused, naming the blob and the field.
    succeeds(&cbd(&dir, &["fit", "--quiet", "--model", "rr.toml", "--data", "train.csv", "--out", "rr.blob"]));
    let blob = std::fs::read(dir.join("rr.blob")).unwrap();
    let sigma = cbd_protocol::decode(&blob).unwrap().noise_sigma.expect("a format-7 blob records its σ");
    for (bad, shown) in [(1e300, "1e300"), (4e-320, "4e-320")] {
        write(&dir, "bad.blob", reframe(&blob, |p| replace_f64(p, sigma, bad, 0)));
        fails_with(
            &cbd(&dir, &["eval", "--model", "rr.toml", "--blob", "bad.blob", "--data", "train.csv"]),
            &["bad.blob: noise_sigma must be a number in [1e-100, 1e100], got ", shown],
        );
    }
    // σ from a flag: the same bound; within it, the figures stay readable.
    fails_with(
        &cbd(&dir, &["fit", "--model", "rr.toml", "--data", "train.csv", "--out", "x.blob", "--sigma", "1e-300"]),
        &["--sigma must be a number in [1e-100, 1e100], got 1e-300"],
    );
    fails_with(
        &cbd(&dir, &["fit", "--model", "rr.toml", "--data", "train.csv", "--out", "x.blob", "--sigma", "1e30"]),
        &["--sigma 1e30 is over 1000 × the spread of train.csv's positions"],
    );
    for sigma in ["1e-30", "100"] {
        let out = cbd(&dir, &["fit", "--quiet", "--model", "rr.toml", "--data", "train.csv", "--out", "s.blob", "--sigma", sigma]);
        let err = succeeds(&out) + &String::from_utf8_lossy(&out.stdout);
        let line = err.lines().find(|l| l.contains("× floor")).unwrap_or_else(|| panic!("{err}"));
        let longest = line.split(|c: char| !c.is_ascii_digit()).map(str::len).max().unwrap_or(0);
        assert!(longest <= 6 && !line.contains(" 0.00 ×") && !line.contains("inf"), "{line}");
    }
    // A value next to an accepted one is echoed as written, never as the accepted one.
    fails_with(
        &cbd(&dir, &["simulate", "--grid", "4", "--out", "e.csv", "--effect", "encoder_scale:joint=1,scale=0.99999999999999999999"]),
        &["scale = 1: an encoder scale error must lie within (-1, 1)"],
    );
    fails_with(
        &cbd(&dir, &["simulate", "--grid", "4", "--out", "e.csv", "--effect", "encoder_scale:joint=1,scale=-1.0000000000000002"]),
        &["scale = -1.0000000000000002:"],
    );
    // Finite but beyond the bound: said so, not "not finite".
    let err = fails_with(
        &cbd(
            &dir,
            &[
                "simulate",
                "--robot",
                "six",
                "--sampling",
                "uniform",
                "--count",
                "20",
                "--out",
                "t.csv",
                "--tracker-frame",
                "1e300,0,0;0,0,1,30",
            ],
        ),
        &["1e300 is beyond ±1e100"],
    );
    assert!(!err.contains("finite"), "{err}");
    // A header with a zero-width space after q1.
    let text = std::fs::read_to_string(dir.join("train.csv")).unwrap().replacen("q1", "q1\u{200b}", 1);
    write(&dir, "zw.csv", text);
    fails_with(
        &cbd(&dir, &["eval", "--model", "rr.toml", "--blob", "rr.blob", "--data", "zw.csv"]),
        &["zw.csv", "header column 1 is q1\\u{200b}", "invisible character U+200B"],
    );
}

/// Class 5: commands that share inputs share the pipeline. `cbd plan --data` registers a base
/// declared unknown as `cbd fit` does, and so chooses what fit chooses on the same rows (it kept the
/// identity base: the nominal chosen, 0.55 mm predicted where fit reaches 0.04 mm); its lines use
/// one meaning of "identified" (the information's rank, as it counts the planned poses).
#[test]
fn plan_registers_and_chooses_as_fit_does_and_counts_identified_poses_once() {
    let dir = scratch("rel5-plan-as-fit");
    let text = std::fs::read_to_string(ur5_dir().join("simulated-six.toml")).unwrap();
    let registered = text.replace("base = { translation = [0, 0, 0], rpy = [0, 0, 0] }", "base = { register = true }");
    assert_ne!(registered, text);
    write(&dir, "tracker.toml", registered);
    let simulate = ["simulate", "--robot", "six", "--sampling", "uniform", "--seed", "2", "--noise", "0.02", "--count", "60"];
    succeeds(&cbd(&dir, &[&simulate[..], &["--tracker-frame", "3000,-2000,1000;1,1,0,30", "--out", "tracker.csv"]].concat()));
    let fit = succeeds(&cbd(&dir, &["fit", "--model", "tracker.toml", "--data", "tracker.csv", "--out", "t.blob"]));
    let plan = ["plan", "--model", "tracker.toml", "--data", "tracker.csv", "--count", "5", "--candidates", "300", "--workspace", "16"];
    let planned = succeeds(&cbd(&dir, &[&plan[..], &["--out", "p.csv", "--json", "p.json"]].concat()));
    let geometry = |err: &str| err.lines().find(|l| l.starts_with("geometry: ")).map(str::to_string);
    assert!(planned.contains("tracker.csv: registered base"), "{planned}");
    assert_eq!(geometry(&planned), geometry(&fit), "plan:\n{planned}\nfit:\n{fit}");
    assert!(geometry(&fit).is_some_and(|g| g.starts_with("geometry: calibrated")), "{fit}");
    let predicted = json(&dir.join("p.json"))["plan"]["measured_predicted_rms"].as_f64().unwrap();
    assert!(predicted < 0.1, "predicted {predicted} mm after the measured poses:\n{planned}");

    // 12 poses identify the group (23 parameters) without coordinates to spare: said once, in the
    // plan's own terms, and the planned poses are not counted as "before it is identified".
    write(&dir, "six.toml", text);
    succeeds(&cbd(&dir, &[&simulate[..9], &["--count", "12", "--out", "twelve.csv"]].concat()));
    let err = succeeds(&cbd(
        &dir,
        &[
            "plan",
            "--model",
            "six.toml",
            "--data",
            "twelve.csv",
            "--count",
            "10",
            "--candidates",
            "300",
            "--workspace",
            "16",
            "--out",
            "q.csv",
        ],
    ));
    assert!(err.contains("twelve.csv: 12 poses identify the geometric group (23 parameters) but leave too few coordinates"), "{err}");
    assert!(!err.contains("do not identify") && !err.contains("before the geometric group"), "{err}");
    assert!(
        err.contains("the geometric group (23 parameters identifiable at the nominal geometry) identified by the measured poses"),
        "{err}"
    );
}

/// Class 4: no line claims a cross-validation the rows could not give (fit said "4-fold
/// cross-validation … on 3 rows" beside the scheme's "too few rows"). Class 6: rows at the nominal
/// (simulated with no error and no noise) name the file and the cause, not "no start gave a
/// positive-definite covariance"; σ and the scales print readably (no 30-digit decimals).
#[test]
fn fit_says_what_it_did_and_why_it_cannot() {
    let dir = scratch("rel5-fit-lines");
    let text = std::fs::read_to_string(ur5_dir().join("simulated-six.toml")).unwrap();
    write(&dir, "six.toml", text.replace("min_rows = 10", "min_rows = 3"));
    succeeds(&cbd(&dir, &["simulate", "--robot", "six", "--sampling", "uniform", "--count", "3", "--seed", "1", "--out", "three.csv"]));
    let fixed = ["--sigma", "0.01", "--gamma", "1e-5", "--joint-b", "0.25", "--task-width", "500", "--task-gamma", "0.4"];
    let err = succeeds(&cbd(&dir, &[&["fit", "--model", "six.toml", "--data", "three.csv", "--out", "t.blob"][..], &fixed[..]].concat()));
    assert!(!err.contains("-fold cross-validation"), "{err}");
    assert!(err.contains("geometry: nominal (too few poses to cross-validate: 3, where 4 folds need at least 8"), "{err}");
    assert!(err.contains("scheme: euler × 1 (too few poses to cross-validate: 3, where 4 folds need at least 8)"), "{err}");

    let exact = ["simulate", "--robot", "six", "--noise", "0", "--sampling", "uniform", "--count", "40", "--exact-geometry"];
    succeeds(&cbd(&dir, &[&exact[..], &["--effect", "thermal:dx=0,dy=0,dz=0", "--out", "exact.csv"]].concat()));
    fails_with(
        &cbd(&dir, &["fit", "--model", "six.toml", "--data", "exact.csv", "--out", "e.blob"]),
        &["exact.csv: the positions are the nominal model's own", "no noise for CbD's evidence to estimate σ from"],
    );
    let rr = rr_grid(&dir, "rr.csv", 6);
    let err = succeeds(&cbd(&dir, &["fit", "--data", &rr, "--out", "rr.blob"]));
    let line = err.lines().find(|l| l.starts_with("hyperparameters")).unwrap();
    assert!(!line.contains("0.0000"), "{line}");
    for word in line.split(|c: char| c == ' ' || c == ';' || c == '[' || c == ']' || c == '=') {
        assert!(word.len() <= 24, "{word:?} in {line}");
    }
}

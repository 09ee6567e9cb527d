//! Issue 51 ("Reliability V") through the real binary. Class 2: a command that fails leaves every
//! output path it was given as it found it — each pre-existing output byte-identical, no new file
//! or directory left behind — whichever output flag and however late the failure.

mod cli_support;

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

//! Issue 52: every command reads its model file once (`cli::ArmModel::read`) and takes all it needs
//! from that parse — units, `register = true`, columns — never from the file again. Counted in
//! process (`data::model_file::parses`), one command after another; this file holds one test so
//! that nothing else parses while it counts.

use clap::Parser;
use std::path::{Path, PathBuf};
use std::process::Command;

const CBD: &str = env!("CARGO_BIN_EXE_cbd");

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).parent().unwrap().to_path_buf()
}

/// Parses `cbd <args>` and runs it here; the model files it parsed.
fn parses_of(args: &[&str]) -> usize {
    let before = cbd_trainer::data::model_file::parses();
    let cli = cbd_trainer::cli::Cli::try_parse_from(std::iter::once("cbd").chain(args.iter().copied())).unwrap();
    cbd_trainer::cli::run(cli).unwrap_or_else(|e| panic!("cbd {}: {e}", args.join(" ")));
    cbd_trainer::data::model_file::parses() - before
}

#[test]
fn each_command_parses_its_model_file_once() {
    let dir = std::env::temp_dir().join(format!("cbd-parsed-once-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let p = |name: &str| dir.join(name).display().to_string();
    // The data by the binary (not counted here): a six-joint arm, 48 training and 12 test poses.
    for (name, count, seed) in [("train.csv", "48", "1"), ("test.csv", "12", "2")] {
        let out = Command::new(CBD)
            .args(["simulate", "--robot", "six", "--sampling", "uniform", "--noise", "0.02", "--count", count, "--seed", seed, "--out"])
            .arg(p(name))
            .output()
            .unwrap();
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    }
    let model = repo().join("examples/ur5/simulated-six.toml").display().to_string();
    let (train, test, blob, poses) = (p("train.csv"), p("test.csv"), p("six.blob"), p("poses.csv"));
    let commands: Vec<Vec<&str>> = vec![
        vec!["fit", "--model", &model, "--data", &train, "--out", &blob, "--geometry", "calibrated", "--quiet"],
        vec!["eval", "--model", &model, "--blob", &blob, "--data", &test],
        vec!["compare", "--model", &model, "--train", &train, "--test", &test],
        vec!["diagnose", "--model", &model, "--data", &train, "--test", &test, "--no-cbd"],
        vec!["plan", "--model", &model, "--data", &train, "--count", "2", "--out", &poses],
        vec!["check", "--model", &model, "--blob", &blob, "--data", &test],
    ];
    let counted: Vec<(String, usize)> = commands.iter().map(|c| (c[0].to_string(), parses_of(c))).collect();
    let _ = std::fs::remove_dir_all(&dir);
    for (command, n) in &counted {
        assert_eq!(*n, 1, "cbd {command} parsed its model file {n} times: {counted:?}");
    }
}

//! One calibration pipeline behind every command: the same data and flags give the same model
//! through `cbd fit` and `cbd compare`; a hyperparameter given by hand as printed reproduces the
//! chosen one exactly; a fit that stalls says so.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use crate::cli_support;

const CBD: &str = env!("CARGO_BIN_EXE_cbd");

fn scratch(name: &str) -> PathBuf {
    cli_support::scratch(&format!("pipeline-{name}"))
}

#[track_caller]
fn cbd(dir: &Path, args: &[&str]) -> Output {
    let out = Command::new(CBD).args(args).current_dir(dir).output().expect("run cbd");
    assert!(out.status.success(), "cbd {args:?} failed:\n{}", String::from_utf8_lossy(&out.stderr));
    out
}

/// A noisy RR training grid (σ = 1e-4), a noise-free random test set, and the planar model file.
fn noisy_rr(dir: &Path, grid: usize) {
    cbd(dir, &["simulate", "--sampling", "grid", "--grid", &grid.to_string(), "--noise", "1e-4", "--out", "train.csv"]);
    cbd(dir, &["simulate", "--sampling", "uniform", "--count", "300", "--seed", "7", "--out", "test.csv"]);
    std::fs::write(
        dir.join("rr.toml"),
        "length_unit = \"m\"\nangle_unit = \"rad\"\n[planar]\nlengths = [1.0, 0.5]\n[measurements]\njoints = [\"q1\", \"q2\"]\npositions = [\"x\", \"y\"]\n",
    )
    .unwrap();
}

fn json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

/// The value after `key ` in the pipeline's hyperparameter line.
fn printed(stderr: &str, key: &str) -> String {
    let line = stderr.lines().find(|l| l.starts_with("hyperparameters")).expect("hyperparameter line");
    let at = line.rfind(key).unwrap_or_else(|| panic!("{key} in {line}")) + key.len();
    line[at..].split(|c: char| c == ';' || c.is_whitespace()).next().unwrap().to_string()
}

#[test]
fn fit_and_compare_give_the_same_model_and_the_printed_sigma_gives_the_same_blob() {
    let dir = scratch("same-model");
    noisy_rr(&dir, 10);
    let fit = cbd(&dir, &["fit", "--model", "rr.toml", "--data", "train.csv", "--out", "a.blob", "--json", "fit.json"]);
    let stderr = String::from_utf8_lossy(&fit.stderr).into_owned();
    // The JSON carries the same choice, in data units, with the evidence and the scheme.
    let chosen = json(&dir.join("fit.json"));
    assert_eq!(Some(chosen["hyperparameters"]["sigma"].as_f64().unwrap()), printed(&stderr, "sigma ").parse::<f64>().ok());
    assert!(chosen["evidence"]["log_evidence"].as_f64().unwrap().is_finite());
    assert_eq!(chosen["scheme"]["chosen_by"].as_str().unwrap(), "4-fold cross-validation");
    cbd(&dir, &["eval", "--model", "rr.toml", "--blob", "a.blob", "--data", "test.csv", "--json", "eval.json"]);
    cbd(&dir, &["compare", "--model", "rr.toml", "--train", "train.csv", "--test", "test.csv", "--json", "compare.json"]);
    let (eval, compare) = (json(&dir.join("eval.json")), json(&dir.join("compare.json")));
    let from_fit = eval["calibrated"]["mean"].as_f64().unwrap();
    let from_compare = compare["methods"]["cbd"]["mean"].as_f64().unwrap();
    // The same predictions (summed in a different order by the two reports).
    assert!((from_fit - from_compare).abs() <= 1e-12 * from_fit, "fit + eval {from_fit:e}, compare {from_compare:e}");

    // σ as printed (data units, shortest round-trip form) replaces the chosen σ by itself.
    let sigma = printed(&stderr, "sigma ");
    cbd(&dir, &["fit", "--model", "rr.toml", "--data", "train.csv", "--out", "b.blob", "--sigma", &sigma]);
    let (a, b) = (std::fs::read(dir.join("a.blob")).unwrap(), std::fs::read(dir.join("b.blob")).unwrap());
    assert!(a == b, "--sigma {sigma} changed the blob");
    // A different σ is a different model.
    let other = format!("{}", sigma.parse::<f64>().unwrap() * 4.0);
    cbd(&dir, &["fit", "--model", "rr.toml", "--data", "train.csv", "--out", "c.blob", "--sigma", &other]);
    assert!(a != std::fs::read(dir.join("c.blob")).unwrap());
    // The evidence's nearly singular kernels: their momenta cancel, but the blob's expansion (what
    // the runtime evaluates) does not, so no warning (issue 25) …
    let report = &chosen["fit"];
    assert_eq!(report["representation"].as_str().unwrap(), "expansion");
    assert!(report["cancellation"].as_f64().unwrap() < 1e3, "{report}");
    assert!(report["kernel_cancellation"].as_f64().unwrap() > 1e5, "{report}");
    assert!(!stderr.contains("cancel to 1 part in"), "{stderr}");
    // … while the kernel form alone warns that it needs f64.
    let kernel = cbd(&dir, &["fit", "--model", "rr.toml", "--data", "train.csv", "--out", "d.blob", "--representation", "kernel"]);
    let kernel_stderr = String::from_utf8_lossy(&kernel.stderr);
    assert!(kernel_stderr.lines().any(|l| l.starts_with("warning: the momenta cancel to 1 part in")), "{kernel_stderr}");
}

#[test]
fn a_fit_stopped_by_the_iteration_limit_warns_with_its_figures() {
    let dir = scratch("stall");
    noisy_rr(&dir, 8);
    let out = cbd(&dir, &["fit", "--data", "train.csv", "--out", "a.blob", "--steps", "2", "--max-iterations", "1"]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    let warning =
        stderr.lines().find(|l| l.starts_with("warning: the fit stopped at the iteration limit")).unwrap_or_else(|| panic!("{stderr}"));
    assert!(warning.contains("training RMS error") && warning.contains("noise level"), "{warning}");
}

//! Issue 27's two properties, over every `cbd` subcommand, through the real binary:
//! - no input makes a subcommand panic or abort: generated bad inputs (few rows, huge and NaN
//!   values, nested and huge files, damaged blobs, odd paths, out-of-range flags) under a memory
//!   limit give exit 1 (or 2 for the argument parser) with one `error:` line, every stderr line at
//!   most 1000 bytes — never 101, 134 or a signal;
//! - no output path destroys an input or a non-regular file, for every flag that writes, each
//!   figure under `--plots` included.

use crate::cli_support;

use cli_support::*;
use std::os::unix::fs::{FileTypeExt, MetadataExt};
use std::os::unix::process::ExitStatusExt;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// Address-space limit of every run (KiB): 400 MB, above the binary's own needs, below a large fit's.
const LIMIT_KIB: u64 = 400_000;

/// Longest a single run may take: a hang (a FIFO written, a read that never ends) fails the test.
const TIMEOUT: Duration = Duration::from_secs(60);

/// What a run gave: its exit code (`None`: killed by a signal, given), stderr.
struct Run {
    code: Option<i32>,
    signal: Option<i32>,
    stderr: String,
}

/// `cbd args` in `dir` under `ulimit -v LIMIT_KIB`, stdout discarded, killed after [`TIMEOUT`].
fn run(dir: &Path, args: &[&str]) -> Run {
    let quoted: Vec<String> = args.iter().map(|a| format!("'{}'", a.replace('\'', "'\\''"))).collect();
    let err_file = dir.join(".stderr");
    let script = format!("ulimit -v {LIMIT_KIB} && exec {CBD} {} 2>'{}'", quoted.join(" "), err_file.display());
    let mut child = Command::new("sh").args(["-c", &script]).current_dir(dir).stdout(Stdio::null()).spawn().expect("run cbd");
    let start = Instant::now();
    let status = loop {
        if let Some(status) = child.try_wait().unwrap() {
            break status;
        }
        if start.elapsed() > TIMEOUT {
            let _ = child.kill();
            let _ = child.wait();
            panic!("cbd {args:?} did not finish in {TIMEOUT:?}");
        }
        std::thread::sleep(Duration::from_millis(5));
    };
    let stderr = String::from_utf8_lossy(&std::fs::read(&err_file).unwrap_or_default()).into_owned();
    Run { code: status.code(), signal: status.signal(), stderr }
}

/// The property for one run on a bad input: exit 1 with one `error:` line, the last, or 2 (the
/// parser's usage error, also one `error:` line); every line at most 1000 bytes. `Err` says how not.
fn refused_cleanly(args: &[&str], r: &Run) -> Result<(), String> {
    let what = format!("cbd {args:?}");
    let excerpt: String = r.stderr.chars().take(2000).collect();
    if r.signal.is_some() || r.stderr.contains("panicked") || r.stderr.contains("memory allocation of") {
        return Err(format!("{what}: signal {:?}, exit {:?}\n{excerpt}", r.signal, r.code));
    }
    if !matches!(r.code, Some(1) | Some(2)) {
        return Err(format!("{what}: exit {:?}\n{excerpt}", r.code));
    }
    let errors = r.stderr.lines().filter(|l| l.starts_with("error: ")).count();
    if errors != 1 {
        return Err(format!("{what}: {errors} `error:` lines\n{excerpt}"));
    }
    let longest = r.stderr.lines().map(str::len).max().unwrap_or(0);
    if longest > 1000 {
        return Err(format!("{what}: a stderr line of {longest} bytes"));
    }
    let last = r.stderr.lines().rev().find(|l| !l.trim().is_empty()).unwrap_or("");
    if r.code == Some(1) && !last.starts_with("error: ") {
        return Err(format!("{what}: the error is not the last line\n{excerpt}"));
    }
    Ok(())
}

/// A 2 GiB file of NUL bytes that takes no disk space: more than the memory limit if read whole.
fn sparse(dir: &Path, name: &str) -> String {
    std::fs::File::create(dir.join(name)).unwrap().set_len(2 << 30).unwrap();
    name.to_string()
}

/// Bad measurement CSVs (RR columns q1, q2, x, y), by file name.
fn bad_csvs(dir: &Path) -> Vec<String> {
    let n = 30_000;
    let mut files = vec![
        write(dir, "empty.csv", ""),
        write(dir, "header.csv", "q1,q2,x,y\n"),
        write(dir, "one.csv", "q1,q2,x,y\n0.1,0.2,1.3,0.4\n"),
        write(dir, "two.csv", "q1,q2,x,y\n0.1,0.2,1.3,0.4\n0.3,0.1,1.2,0.5\n"),
        write(dir, "nan.csv", "q1,q2,x,y\n0.1,0.2,1.3,0.4\n0.3,NaN,1.2,0.5\n0.5,0.1,1.1,0.6\n"),
        write(dir, "huge.csv", "q1,q2,x,y\n0.1,0.2,1.3,0.4\n0.3,0.1,1e300,0.5\n0.5,0.1,1.1,0.6\n"),
        write(dir, "inf.csv", "q1,q2,x,y\n0.1,0.2,1.3,0.4\n0.3,0.1,-inf,0.5\n0.5,0.1,1.1,0.6\n"),
        write(dir, "angle.csv", "q1,q2,x,y\n0.1,0.2,1.3,0.4\n1e200,0.1,1.2,0.5\n0.5,0.1,1.1,0.6\n"),
        write(dir, "fields.csv", "q1,q2,x,y\n0.1,0.2,1.3,0.4,9\n"),
        write(dir, "columns.csv", "a,b,c\n1,2,3\n4,5,6\n"),
        write(dir, "same.csv", "q1,q2,x,y\n".to_string() + &"0.1,0.2,1.3,0.4\n".repeat(50)),
        write(dir, "text.csv", "q1,q2,x,y\n".to_string() + &"z".repeat(60_000) + ",1,2,3\n"),
        write(dir, "longline.csv", "q1,q2,x,y\n".to_string() + &"1".repeat(100_000) + "\n"),
        write(dir, "nul.csv", vec![0u8; 1 << 20]),
        write(dir, "utf.csv", b"q1,q2,x,y\n\xff\xfe,1,2,3\n".to_vec()),
        write(dir, "deep.csv", format!("q1,q2,x,y\n{}\n", "\"".repeat(n))),
    ];
    files.push(sparse(dir, "sparse.csv"));
    files.push("missing.csv".into());
    files.push("adir".into());
    files.push("/dev/null".into());
    files.push("odd\nname.csv".into());
    files
}

/// Bad model files (TOML), by file name.
fn bad_models(dir: &Path) -> Vec<String> {
    let n = 30_000;
    write(dir, "deep.urdf", format!("<robot name=\"r\">{}{}</robot>", "<a>".repeat(n), "</a>".repeat(n)));
    let urdf = |name: &str, urdf: &str| {
        write(
            dir,
            name,
            format!("length_unit = \"m\"\nangle_unit = \"rad\"\n[urdf]\npath = \"{urdf}\"\nbase_link = \"a\"\ntip_link = \"b\"\n"),
        )
    };
    vec![
        write(dir, "garbage.toml", "[[[ this is not toml"),
        write(dir, "empty.toml", ""),
        write(dir, "hugelen.toml", PLANAR_RR_MODEL.replace("[1.0, 0.5]", "[1e300, 0.5]")),
        write(dir, "nanlen.toml", PLANAR_RR_MODEL.replace("[1.0, 0.5]", "[nan, 0.5]")),
        write(dir, "nojoints.toml", PLANAR_RR_MODEL.replace("[1.0, 0.5]", "[]")),
        write(dir, "deeptoml.toml", format!("x = {}{}\n", "[".repeat(n), "]".repeat(n))),
        write(dir, "units.toml", PLANAR_RR_MODEL.replace("\"m\"", "\"furlong\"")),
        urdf("deepurdf.toml", "deep.urdf"),
        urdf("nourdf.toml", "none.urdf"),
        sparse(dir, "sparse.toml"),
        urdf("sparseurdf.toml", &sparse(dir, "sparse.urdf")),
        "missing.toml".into(),
        "adir".into(),
    ]
}

/// Bad blobs, by file name: truncated, a flipped bit, checksum-valid but damaged, not a blob.
fn bad_blobs(dir: &Path, good: &str) -> Vec<String> {
    let bytes = std::fs::read(dir.join(good)).unwrap();
    let mut flipped = bytes.clone();
    let mid = flipped.len() / 2;
    flipped[mid] ^= 0x10;
    vec![
        write(dir, "empty.blob", ""),
        write(dir, "half.blob", &bytes[..bytes.len() / 2]),
        write(dir, "flip.blob", flipped),
        damaged_blob(dir, good, "damaged.blob", 1e150),
        write(dir, "csv.blob", "q1,q2,x,y\n0,0,1,0\n"),
        write(dir, "big.blob", vec![7u8; 70 << 20]),
        sparse(dir, "sparse.blob"),
        "missing.blob".into(),
        "adir".into(),
    ]
}

/// Bad run JSONs for `report`, by file name.
fn bad_jsons(dir: &Path) -> Vec<String> {
    vec![
        write(dir, "empty.json", ""),
        write(dir, "obj.json", "{}"),
        write(dir, "list.json", "[1, 2]"),
        write(dir, "deep.json", format!("{}{}", "[".repeat(100_000), "]".repeat(100_000))),
        write(dir, "nanstats.json", "{\"nominal\": {\"mean\": 1e999, \"median\": \"x\", \"p99\": null, \"max\": -1}}"),
        write(dir, "hugestr.json", format!("{{\"unit\": \"{}\"}}", "u".repeat(200_000))),
        sparse(dir, "sparse.json"),
        "missing.json".into(),
        "adir".into(),
    ]
}

/// Replaces the value after `flag` in `base` by `value` (or appends `flag value`).
fn with(base: &[&str], flag: &str, value: &str) -> Vec<String> {
    let mut args: Vec<String> = base.iter().map(|s| s.to_string()).collect();
    match args.iter().position(|a| a == flag) {
        Some(i) => args[i + 1] = value.to_string(),
        None => args.extend([flag.to_string(), value.to_string()]),
    }
    args
}

/// The planar RR arm with joint limits (`cbd plan` needs them).
const RR_MODEL_WITH_LIMITS: &str =
    "length_unit = \"m\"\nangle_unit = \"rad\"\n[planar]\nlengths = [1.0, 0.5]\n[measurements]\njoints = [\"q1\", \"q2\"]\npositions = [\"x\", \"y\"]\njoint_limits = [[-3.1, 3.1], [0.1, 3.0]]\n";

const GIVEN: [&str; 12] =
    ["--joint-b", "0.001", "--gamma", "1", "--task-width", "10", "--task-gamma", "1", "--sigma", "1e-4", "--steps", "1"];

#[test]
fn no_input_makes_any_subcommand_panic_or_abort() {
    let dir = scratch("property-inputs");
    std::fs::create_dir(dir.join("adir")).unwrap();
    rr_grid(&dir, "g4.csv", 4);
    succeeds(&cbd(&dir, &["simulate", "--sampling", "uniform", "--count", "20", "--seed", "3", "--out", "t.csv"]));
    write(&dir, "rr.toml", PLANAR_RR_MODEL);
    write(&dir, "rr-limits.toml", RR_MODEL_WITH_LIMITS);
    write(&dir, "targets.csv", "x,y\n1.2,0.3\n0.5,0.5\n");
    let mut fit = vec!["fit", "--data", "g4.csv", "--out", "a.blob", "--quiet"];
    fit.extend(GIVEN);
    succeeds(&cbd(&dir, &fit));
    let mut compare = vec!["compare", "--model", "rr.toml", "--train", "g4.csv", "--test", "t.csv", "--json", "run.json"];
    compare.extend(GIVEN);
    succeeds(&cbd(&dir, &compare));

    let mut cases: Vec<Vec<String>> = Vec::new();
    let mut csv_slot = |base: &[&str], flag: &str, files: &[String]| {
        for f in files {
            cases.push(with(base, flag, f));
        }
    };
    let csvs = bad_csvs(&dir);
    let models = bad_models(&dir);
    let blobs = bad_blobs(&dir, "a.blob");
    let jsons = bad_jsons(&dir);

    let fit_base = fit.clone();
    let eval_base = ["eval", "--blob", "a.blob", "--data", "t.csv"];
    let comp_base = ["compensate", "--blob", "a.blob", "--targets", "targets.csv", "--out", "c.csv"];
    let mut diag_base = vec!["diagnose", "--model", "rr.toml", "--data", "g4.csv", "--test", "t.csv"];
    diag_base.extend(GIVEN);
    let mut cmp_base = vec!["compare", "--model", "rr.toml", "--train", "g4.csv", "--test", "t.csv"];
    cmp_base.extend(GIVEN);
    let report_base = ["report", "--json", "run.json", "--out", "r.html"];
    let plan_base = ["plan", "--model", "rr-limits.toml", "--count", "3", "--candidates", "200", "--workspace", "16", "--out", "p.csv"];

    for (base, flag) in [
        (&fit_base[..], "--data"),
        (&eval_base[..], "--data"),
        (&comp_base[..], "--targets"),
        (&comp_base[..], "--seeds"),
        (&diag_base[..], "--data"),
        (&diag_base[..], "--test"),
        (&cmp_base[..], "--train"),
        (&cmp_base[..], "--test"),
        (&plan_base[..], "--data"),
        (&plan_base[..], "--candidate-file"),
    ] {
        // The few-row files are valid data for some commands (three rows fit); the rest are bad.
        let bad: Vec<String> = csvs.iter().filter(|f| !(f.as_str() == "same.csv" && flag == "--test")).cloned().collect();
        csv_slot(base, flag, &bad);
    }
    for (base, flag) in [
        (&fit_base[..], "--model"),
        (&eval_base[..], "--model"),
        (&comp_base[..], "--model"),
        (&diag_base[..], "--model"),
        (&cmp_base[..], "--model"),
        (&plan_base[..], "--model"),
    ] {
        csv_slot(base, flag, &models);
    }
    for base in [&eval_base[..], &comp_base[..]] {
        csv_slot(base, "--blob", &blobs);
    }
    csv_slot(&report_base, "--json", &jsons);
    csv_slot(&report_base, "--plots", &["missing".into(), "g4.csv".into()]);

    // Flags out of range, huge or not numbers, on every subcommand.
    let numbers = ["nan", "inf", "-1", "0", "1e300", "1000000", "4294967297", "99999999999999999999", "abc", ""];
    let demo_base = [
        "demo",
        "--grid",
        "3",
        "--test-points",
        "10",
        "--out",
        "d.blob",
        "--quiet",
        "--joint-b",
        "0.001",
        "--gamma",
        "1",
        "--task-width",
        "10",
        "--task-gamma",
        "1",
        "--sigma",
        "1e-4",
        "--steps",
        "1",
    ];
    let sim_base = ["simulate", "--grid", "3", "--out", "s.csv"];
    let bench_base = ["bench", "--sizes", "4", "--evidence-sizes", "4", "--no-ur5", "--json", "b.json"];
    let numeric: Vec<(&[&str], &str)> = vec![
        (&fit_base, "--sigma"),
        (&fit_base, "--task-width"),
        (&fit_base, "--joint-b"),
        (&fit_base, "--steps"),
        (&fit_base, "--max-rows"),
        (&fit_base, "--max-iterations"),
        (&eval_base, "--extrapolation-threshold"),
        (&comp_base, "--iterations"),
        (&comp_base, "--tolerance"),
        (&diag_base, "--harmonics"),
        (&diag_base, "--folds"),
        (&diag_base, "--margin"),
        (&cmp_base, "--gamma"),
        (&demo_base, "--grid"),
        (&demo_base, "--test-points"),
        (&demo_base, "--task-gamma"),
        (&sim_base, "--grid"),
        (&sim_base, "--noise"),
        (&bench_base, "--sizes"),
        (&bench_base, "--evidence-sizes"),
        (&plan_base, "--count"),
        (&plan_base, "--candidates"),
        (&plan_base, "--workspace"),
        (&plan_base, "--noise"),
        (&plan_base, "--prior-error"),
        (&plan_base, "--seed"),
    ];
    for (base, flag) in numeric {
        for v in numbers {
            let args = with(base, flag, v);
            // A few of these are valid (e.g. `--max-rows 0` … is not; `--noise 0` is): only failures are judged.
            cases.push(args);
        }
    }
    for extra in [
        vec!["simulate", "--sampling", "uniform", "--count", "100000000000", "--out", "s.csv"],
        vec!["simulate", "--effect", "bogus:x=1", "--out", "s.csv"],
        vec!["simulate", "--effect", "thermal:dx=nan", "--out", "s.csv"],
        vec!["simulate", "--robot", "nine", "--out", "s.csv"],
        vec!["demo", "--hyperparameters", "nonsense", "--out", "d.blob"],
        vec!["demo", "--grid", "3000", "--out", "d.blob"],
        vec!["demo", "--grid", "4", "--test-points", "100000000000", "--out", "d.blob"],
        vec!["demo", "--grid", "5000000000", "--hyperparameters", "evidence", "--out", "d.blob"],
        vec!["bench", "--sizes", "4", "--evidence-sizes", "4", "--ur5", "adir", "--json", "b.json"],
        vec!["compare", "--model", "rr.toml", "--train", "g4.csv", "--test", "t.csv", "--commanded", "ten"],
        vec!["fit", "--data", "g4.csv", "--out", "a2.blob", "--integrator", "leapfrog"],
        vec!["fit", "--data", "g4.csv", "--out", "a2.blob", "--solver", "magic"],
        vec!["nosuchcommand"],
    ] {
        cases.push(extra.iter().map(|s| s.to_string()).collect());
    }

    let (mut judged, mut failures) = (0, Vec::new());
    for args in &cases {
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let r = run(&dir, &args);
        if r.code == Some(0) {
            // Accepted (valid after all: `--noise 0`, three rows, `--sizes 4`): not a refusal to
            // judge, but never with a panic's text.
            if r.stderr.contains("panicked") {
                failures.push(format!("cbd {args:?}: exit 0 with a panic\n{}", r.stderr));
            }
            continue;
        }
        judged += 1;
        if let Err(e) = refused_cleanly(&args, &r) {
            failures.push(e);
        }
    }
    eprintln!("{} cases, {judged} refused", cases.len());
    assert!(failures.is_empty(), "{} of {} cases:\n{}", failures.len(), cases.len(), failures.join("\n\n"));
    // Nearly every case is bad input: the property was checked on them, not skipped.
    assert!(judged * 10 >= cases.len() * 8, "only {judged} of {} cases failed", cases.len());
    // The valid base commands still work (the bad value, not the command, was refused).
    for base in [&eval_base[..], &comp_base[..], &report_base[..], &sim_base[..], &plan_base[..]] {
        let r = run(&dir, base);
        assert_eq!(r.code, Some(0), "cbd {base:?}\n{}", r.stderr);
    }
}

/// What a path is before and after a run: its type, and for files their bytes, for links their
/// target, the target's bytes.
#[derive(PartialEq, Debug)]
enum State {
    Missing,
    File(Vec<u8>, u64),
    Link(std::path::PathBuf, Option<Vec<u8>>),
    Fifo,
    Dir,
    Other,
}

fn state(p: &Path) -> State {
    let Ok(m) = std::fs::symlink_metadata(p) else { return State::Missing };
    let t = m.file_type();
    if t.is_symlink() {
        State::Link(std::fs::read_link(p).unwrap(), std::fs::read(p).ok())
    } else if t.is_file() {
        State::File(std::fs::read(p).unwrap(), m.ino())
    } else if t.is_fifo() {
        State::Fifo
    } else if t.is_dir() {
        State::Dir
    } else {
        State::Other
    }
}

#[test]
fn no_output_path_destroys_an_input_or_a_non_regular_file() {
    let dir = scratch("property-outputs");
    rr_grid(&dir, "g4.csv", 4);
    succeeds(&cbd(&dir, &["simulate", "--sampling", "uniform", "--count", "20", "--seed", "3", "--out", "t.csv"]));
    write(&dir, "rr.toml", PLANAR_RR_MODEL);
    write(&dir, "targets.csv", "x,y\n1.2,0.3\n0.5,0.5\n");
    write(&dir, "seeds.csv", "q1,q2\n0.5,0.5\n0.6,0.4\n");
    write(&dir, "rr-limits.toml", RR_MODEL_WITH_LIMITS);
    write(&dir, "precious.txt", "precious");
    let mut fit = vec!["fit", "--model", "rr.toml", "--data", "g4.csv", "--out", "a.blob", "--quiet"];
    fit.extend(GIVEN);
    succeeds(&cbd(&dir, &fit));
    let mut cmp = vec!["compare", "--model", "rr.toml", "--train", "g4.csv", "--test", "t.csv", "--json", "run.json"];
    cmp.extend(GIVEN);
    succeeds(&cbd(&dir, &cmp));
    let mut diag = vec!["diagnose", "--model", "rr.toml", "--data", "g4.csv", "--test", "t.csv", "--json", "diag.json"];
    diag.extend(GIVEN);
    let mut demo = vec!["demo", "--grid", "3", "--test-points", "10", "--out", "d.blob", "--json", "demo.json", "--quiet"];
    demo.extend(GIVEN);

    // Every command with every flag that writes, and its inputs' flags.
    let commands: Vec<(Vec<&str>, Vec<&str>, Vec<&str>)> = vec![
        (fit.clone(), vec!["--out", "--json"], vec!["--model", "--data"]),
        (
            vec!["eval", "--model", "rr.toml", "--blob", "a.blob", "--data", "t.csv", "--json", "e.json"],
            vec!["--json", "--plots"],
            vec!["--model", "--blob", "--data"],
        ),
        (
            vec![
                "compensate",
                "--model",
                "rr.toml",
                "--blob",
                "a.blob",
                "--targets",
                "targets.csv",
                "--seeds",
                "seeds.csv",
                "--out",
                "c.csv",
                "--json",
                "c.json",
            ],
            vec!["--out", "--json"],
            vec!["--model", "--blob", "--targets", "--seeds"],
        ),
        (vec!["report", "--json", "run.json", "--out", "r.html"], vec!["--out"], vec!["--json"]),
        (diag.clone(), vec!["--json", "--plots", "--write-model"], vec!["--model", "--data", "--test"]),
        (cmp.clone(), vec!["--json", "--plots"], vec!["--model", "--train", "--test"]),
        (vec!["simulate", "--grid", "3", "--out", "s.csv"], vec!["--out"], vec![]),
        (
            vec![
                "plan",
                "--model",
                "rr-limits.toml",
                "--data",
                "g4.csv",
                "--candidate-file",
                "seeds.csv",
                "--count",
                "2",
                "--candidates",
                "100",
                "--workspace",
                "8",
                "--out",
                "p.csv",
                "--json",
                "p.json",
            ],
            vec!["--out", "--json"],
            vec!["--model", "--data", "--candidate-file"],
        ),
        (demo.clone(), vec!["--out", "--json", "--plots"], vec![]),
        (vec!["bench", "--sizes", "4", "--evidence-sizes", "4", "--no-ur5", "--json", "b.json"], vec!["--json", "--markdown"], vec![]),
    ];
    std::fs::create_dir(dir.join("adir")).unwrap();
    assert!(Command::new("mkfifo").arg(dir.join("fifo")).status().unwrap().success());
    std::os::unix::fs::symlink("precious.txt", dir.join("link")).unwrap();
    std::os::unix::fs::symlink("nowhere", dir.join("dangling")).unwrap();
    let mut runs = 0;
    let check = |args: &[String], victims: &[std::path::PathBuf]| {
        let before: Vec<State> = victims.iter().map(|v| state(v)).collect();
        let precious = state(&dir.join("precious.txt"));
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let r = run(&dir, &args);
        assert!(r.signal.is_none() && !r.stderr.contains("panicked"), "cbd {args:?}\n{}", r.stderr);
        for (v, b) in victims.iter().zip(&before) {
            assert_eq!(&state(v), b, "cbd {args:?} changed {}\n{}", v.display(), r.stderr);
        }
        assert_eq!(state(&dir.join("precious.txt")), precious, "cbd {args:?} changed precious.txt");
    };
    for (base, outputs, inputs) in &commands {
        for out in outputs {
            if *out == "--plots" {
                continue;
            }
            let mut victims: Vec<String> = inputs.iter().map(|i| base[base.iter().position(|a| a == i).unwrap() + 1].to_string()).collect();
            victims.extend(["adir", "fifo", "link", "dangling", "/dev/null"].map(String::from));
            for victim in victims {
                // A hard link to an input is the same file by another name.
                let names = if Path::new(&victim).is_file() && !victim.starts_with('/') && victim != "link" {
                    let hard = format!("hard-{victim}");
                    let _ = std::fs::remove_file(dir.join(&hard));
                    std::fs::hard_link(dir.join(&victim), dir.join(&hard)).unwrap();
                    vec![victim.clone(), hard]
                } else {
                    vec![victim.clone()]
                };
                for name in names {
                    let path = if name.starts_with('/') { name.clone().into() } else { dir.join(&name) };
                    check(&with(base, out, &name), &[path]);
                    runs += 1;
                }
            }
        }
        // `--plots`: each figure the command writes, found by a run into a fresh directory, replaced
        // by a link to a precious file, a FIFO, a directory and a hard link to an input.
        if outputs.contains(&"--plots") {
            let fresh = format!("plots-{}", base[0]);
            let _ = std::fs::remove_dir_all(dir.join(&fresh));
            let r = run(&dir, &with(base, "--plots", &fresh).iter().map(String::as_str).collect::<Vec<_>>());
            assert_eq!(r.code, Some(0), "{}: {}", base[0], r.stderr);
            let figures: Vec<String> =
                std::fs::read_dir(dir.join(&fresh)).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
            assert!(!figures.is_empty(), "{}: no figures", base[0]);
            // The figures must not replace an input either: a hard link to one where a figure goes.
            let input = inputs.last().map(|flag| dir.join(base[base.iter().position(|a| a == flag).unwrap() + 1]));
            for figure in &figures {
                let plots = format!("victims-{}", base[0]);
                for kind in ["link", "fifo", "dir", "hard"].into_iter().filter(|k| *k != "hard" || input.is_some()) {
                    let _ = std::fs::remove_dir_all(dir.join(&plots));
                    std::fs::create_dir(dir.join(&plots)).unwrap();
                    let victim = dir.join(&plots).join(figure);
                    match kind {
                        "link" => std::os::unix::fs::symlink("../precious.txt", &victim).unwrap(),
                        "fifo" => assert!(Command::new("mkfifo").arg(&victim).status().unwrap().success()),
                        "dir" => std::fs::create_dir(&victim).unwrap(),
                        _ => std::fs::hard_link(input.as_ref().unwrap(), &victim).unwrap(),
                    }
                    let victims: Vec<std::path::PathBuf> = std::iter::once(victim).chain(input.clone()).collect();
                    check(&with(base, "--plots", &plots), &victims);
                    runs += 1;
                }
            }
        }
    }
    assert!(runs > 100, "{runs} runs");
}

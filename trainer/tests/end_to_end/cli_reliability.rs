//! Issue 27 ("no input crashes `cbd`, no output destroys a file, no damaged model is used"): one
//! test per item, through the real binary.

use crate::cli_support;

use cli_support::*;

/// Item 1: a DH or planar fit on fewer measured coordinates than parameters indexed past the thin
/// SVD (`index out of bounds: the len is 30 but the index is 30`). Now fitted (rank-deficient DH,
/// minimum norm); two rows are refused as too few.
#[test]
fn few_rows_in_dh_and_planar_fits() {
    let dir = scratch("few-rows");
    let ur10 = ur5_head(&dir, "ur10.csv", 10);
    let model = ur5_model();
    let err = succeeds(&cbd(&dir, &["fit", "--dh-first", "--model", &model, "--data", &ur10, "--out", "x.blob", "--quiet"]));
    assert!(err.contains("DH calibration") && err.contains("rank"), "{err}");
    succeeds(&cbd(&dir, &["compare", "--model", &model, "--train", &ur10, "--test", &ur10]));
    let planar = write(&dir, "rr.toml", PLANAR_RR_MODEL);
    let grid = rr_grid(&dir, "g4.csv", 4);
    for rows in [8, 3] {
        let few = head(&dir, &grid, &format!("p{rows}.csv"), rows);
        succeeds(&cbd(&dir, &["compare", "--model", &planar, "--train", &few, "--test", &few]));
    }
    let two = head(&dir, &grid, "p2.csv", 2);
    fails_with(&cbd(&dir, &["fit", "--data", &two, "--out", "x.blob"]), &["p2.csv", "2", "at least 3"]);
}

/// Item 4: a URDF of 30 000 nested elements (210 KB) overflowed the stack (abort). Now refused
/// with the URDF's name, line and column.
#[test]
fn deeply_nested_urdf_is_refused() {
    let dir = scratch("deep-urdf");
    let n = 30_000;
    write(&dir, "deep.urdf", format!("<robot name=\"r\">{}{}</robot>", "<a>".repeat(n), "</a>".repeat(n)));
    let model = write(
        &dir,
        "deep.toml",
        "length_unit = \"m\"\nangle_unit = \"rad\"\n[urdf]\npath = \"deep.urdf\"\nbase_link = \"a\"\ntip_link = \"b\"\n",
    );
    let grid = rr_grid(&dir, "g4.csv", 4);
    fails_with(
        &cbd(&dir, &["fit", "--model", &model, "--data", &grid, "--out", "d.blob"]),
        &["deep.urdf", "line 1", "nested more than 64 deep"],
    );
}

/// Item 5: `--plots DIR` wrote through a symbolic link named like a figure (the linked file became
/// an SVG) and blocked forever on a FIFO of that name. Each figure is now written as every output
/// is: the link and the FIFO are refused (exit 1) and left as they were.
#[test]
fn plots_never_write_through_links_or_into_fifos() {
    let dir = scratch("plots-special");
    let grid = rr_grid(&dir, "g4.csv", 4);
    succeeds(&cbd(&dir, &["fit", "--data", &grid, "--out", "a.blob", "--max-iterations", "1", "--quiet"]));
    std::fs::create_dir(dir.join("pl")).unwrap();
    write(&dir, "keep.txt", "keep");
    std::os::unix::fs::symlink("../keep.txt", dir.join("pl/error_histogram.svg")).unwrap();
    let eval = |plots: &str| cbd(&dir, &["eval", "--blob", "a.blob", "--data", &grid, "--plots", plots]);
    fails_with(&eval("pl"), &["pl/error_histogram.svg", "symbolic link"]);
    assert_eq!(std::fs::read_to_string(dir.join("keep.txt")).unwrap(), "keep");
    std::fs::remove_file(dir.join("pl/error_histogram.svg")).unwrap();
    assert!(std::process::Command::new("mkfifo").arg(dir.join("pl/error_heatmaps.png")).status().unwrap().success());
    // A FIFO nobody reads would block a writer forever: the test fails by timeout if it does.
    fails_with(&eval("pl"), &["pl/error_heatmaps.png", "FIFO"]);
    std::fs::remove_file(dir.join("pl/error_heatmaps.png")).unwrap();
    let out = eval("pl");
    succeeds(&out);
    assert!(std::fs::read(dir.join("pl/error_heatmaps.png")).unwrap().starts_with(b"\x89PNG"));
    // A file where the directory goes is refused before the evaluation.
    fails_with(&eval(&grid), &["g4.csv", "not a directory", "--plots"]);
}

/// Item 6: an output path equal to an input silently replaced the input. Every command now refuses,
/// naming the flag of the input, before any work, and the input is unchanged; a hard link to an
/// input is the same file; two outputs on one path are refused too.
#[test]
fn an_output_never_replaces_an_input() {
    let dir = scratch("output-is-input");
    let grid = rr_grid(&dir, "tr.csv", 4);
    succeeds(&cbd(&dir, &["fit", "--data", &grid, "--out", "a.blob", "--max-iterations", "1", "--quiet"]));
    write(&dir, "t.csv", "x,y\n1.2,0.3\n");
    write(&dir, "d.json", "{\"nominal\": {\"mean\": 1, \"median\": 1, \"p99\": 1, \"max\": 1}}");
    std::fs::hard_link(dir.join("tr.csv"), dir.join("hard.csv")).unwrap();
    let before: Vec<Vec<u8>> = ["tr.csv", "a.blob", "t.csv", "d.json"].iter().map(|f| std::fs::read(dir.join(f)).unwrap()).collect();
    for (args, needles) in [
        (vec!["fit", "--data", "tr.csv", "--out", "tr.csv"], vec!["tr.csv: is also an input (--data)"]),
        (vec!["fit", "--data", "tr.csv", "--out", "hard.csv"], vec!["hard.csv: is also an input (--data)"]),
        (vec!["fit", "--data", "tr.csv", "--out", "x.blob", "--json", "x.blob"], vec!["x.blob: is given to both --out and --json"]),
        (vec!["eval", "--blob", "a.blob", "--data", "tr.csv", "--json", "a.blob"], vec!["a.blob: is also an input (--blob)"]),
        (vec!["compensate", "--blob", "a.blob", "--targets", "t.csv", "--out", "t.csv"], vec!["t.csv: is also an input (--targets)"]),
        (vec!["report", "--json", "d.json", "--out", "d.json"], vec!["d.json: is also an input (--json)"]),
        (vec!["diagnose", "--data", "tr.csv", "--json", "tr.csv"], vec!["tr.csv: is also an input (--data)"]),
        (vec!["compare", "--model", "m.toml", "--train", "tr.csv", "--test", "tr.csv", "--json", "tr.csv"], vec!["is also an input"]),
    ] {
        write(&dir, "m.toml", PLANAR_RR_MODEL);
        let err = fails_with(&cbd(&dir, &args), &needles);
        assert!(!err.contains("hyperparameters") && !err.contains("fitted"), "{args:?}: work ran before the check:\n{err}");
    }
    let after: Vec<Vec<u8>> = ["tr.csv", "a.blob", "t.csv", "d.json"].iter().map(|f| std::fs::read(dir.join(f)).unwrap()).collect();
    assert!(before == after, "an input changed");
}

/// Item 7: an interrupted write left its hidden temporary file (`.NAME.tmpPID-0`, 76 MB on a large
/// simulation). The data is now written to an unnamed file that gets its name only when complete:
/// `simulate` killed at any moment leaves no hidden file, and the output is absent or whole.
#[test]
fn an_interrupted_write_leaves_no_hidden_file() {
    let dir = scratch("interrupted-write");
    for delay_ms in [100u64, 300, 500, 700, 900, 1100, 1400] {
        let _ = std::fs::remove_file(dir.join("big.csv"));
        let mut child = std::process::Command::new(CBD)
            .args(["simulate", "--sampling", "uniform", "--count", "1500000", "--out", "big.csv"])
            .current_dir(&dir)
            .stderr(std::process::Stdio::null())
            .spawn()
            .unwrap();
        std::thread::sleep(std::time::Duration::from_millis(delay_ms));
        let _ = child.kill();
        let _ = child.wait();
        let hidden: Vec<String> = std::fs::read_dir(&dir)
            .unwrap()
            .filter_map(|e| e.ok())
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .filter(|n| n.starts_with('.'))
            .collect();
        assert!(hidden.is_empty(), "killed after {delay_ms} ms: {hidden:?}");
        if let Ok(text) = std::fs::read_to_string(dir.join("big.csv")) {
            assert_eq!(text.lines().count(), 1_500_001, "killed after {delay_ms} ms: a partial output");
        }
    }
}

/// Item 10: 100 MB of NUL bytes took 619 MB and echoed the whole "header" to stderr; a 300 MB
/// field gave 300 MB of stderr. Binary data and overlong lines are refused before the CSV reader
/// holds them (here under a 400 MB address-space limit), every message quotes at most an excerpt.
#[test]
fn csv_reading_is_capped_and_quotes_only_excerpts() {
    let dir = scratch("csv-caps");
    std::fs::File::create(dir.join("nul.csv")).unwrap().set_len(100_000_000).unwrap();
    let err =
        fails_with(&cbd_limited(&dir, 400_000, &["fit", "--data", "nul.csv", "--out", "n.blob"]), &["nul.csv:1", "NUL", "not CSV text"]);
    assert!(err.len() < 200, "{err}");
    let field = "1".repeat(70_000_000);
    write(&dir, "long.csv", format!("q1,q2,x,y\n{field},2,3,4\n"));
    let err = fails_with(&cbd_limited(&dir, 600_000, &["eval", "--blob", "none.blob", "--data", "long.csv"]), &["long.csv:2", "64 KiB"]);
    assert!(err.len() < 200, "{err}");
    write(&dir, "word.csv", format!("q1,q2,x,y\n{},2,3,4\n", "z".repeat(60_000)));
    let err = fails_with(
        &cbd(&dir, &["fit", "--data", "word.csv", "--out", "n.blob"]),
        &["word.csv:2", "column 'q1'", "not a number", "(60000 bytes)"],
    );
    assert!(err.len() < 200, "{err}");
}

/// Item 8: `compensate` on a checksum-valid but damaged blob (one `eval` refuses) exited 0 with
/// `residual median NaN`, commands of −2.17e217 and JSON nulls; `eval` blamed a data line. Both
/// now refuse the blob itself, before any target or row, and write nothing.
#[test]
fn a_damaged_blob_is_refused_by_eval_and_compensate() {
    let dir = scratch("damaged-blob");
    let grid = rr_grid(&dir, "g4.csv", 4);
    succeeds(&cbd(&dir, &["fit", "--data", &grid, "--out", "a.blob", "--representation", "kernel", "--quiet"]));
    let bad = damaged_blob(&dir, "a.blob", "bad.blob", 1e150);
    write(&dir, "t.csv", "x,y\n1.2,0.3\n0.5,0.5\n");
    let needles = ["bad.blob", "at its own training configuration", "the blob is damaged"];
    fails_with(&cbd(&dir, &["eval", "--blob", &bad, "--data", &grid]), &needles);
    fails_with(&cbd(&dir, &["compensate", "--blob", &bad, "--targets", "t.csv", "--out", "c.csv", "--json", "c.json"]), &needles);
    assert!(!dir.join("c.csv").exists() && !dir.join("c.json").exists());
    // The undamaged blob still compensates.
    succeeds(&cbd(&dir, &["compensate", "--blob", "a.blob", "--targets", "t.csv", "--out", "c.csv"]));
}

/// Item 9: seeds of 1e200 were accepted and echoed, a target row with more fields than the header
/// was accepted, and a finite but huge target was blamed on the inverse kinematics ("row 0", no
/// line). Targets and seeds are now read as measurement files are: file, line and column.
#[test]
fn compensate_validates_targets_and_seeds_like_measurements() {
    let dir = scratch("compensate-inputs");
    let grid = rr_grid(&dir, "g4.csv", 4);
    succeeds(&cbd(&dir, &["fit", "--data", &grid, "--out", "a.blob", "--quiet"]));
    write(&dir, "t.csv", "x,y\n1.2,0.3\n");
    write(&dir, "s.csv", "q1,q2\n1e200,0\n");
    let compensate = |targets: &str, seeds: Option<&str>| {
        let mut args = vec!["compensate", "--blob", "a.blob", "--targets", targets, "--out", "c.csv"];
        args.extend(seeds.map(|s| ["--seeds", s]).into_iter().flatten());
        cbd(&dir, &args)
    };
    fails_with(&compensate("t.csv", Some("s.csv")), &["s.csv:2: column 'q1'", "1e200 rad is outside the joint's range"]);
    write(&dir, "wide.csv", "x,y\n1.2,0.3,7\n");
    fails_with(&compensate("wide.csv", None), &["wide.csv:2: 3 fields; the header has 2"]);
    write(&dir, "huge.csv", "x,y\n0.5,0.5\n1e300,0\n");
    let err = fails_with(&compensate("huge.csv", None), &["huge.csv:3: column 'x'", "within ±1e100"]);
    assert!(!err.contains("row ") && !err.contains("inverse kinematics"), "{err}");
    // Without --model the arm is the built-in RR arm, and the message says so.
    let six = cbd(&dir, &["simulate", "--robot", "six", "--sampling", "uniform", "--count", "30", "--out", "six.csv"]);
    succeeds(&six);
    succeeds(&cbd(&dir, &["fit", "--model", &ur5_model(), "--data", "six.csv", "--out", "six.blob", "--quiet"]));
    fails_with(&compensate_with_blob(&dir, "six.blob"), &["six.blob", "the built-in RR arm (no --model given)"]);
}

fn compensate_with_blob(dir: &std::path::Path, blob: &str) -> std::process::Output {
    cbd(dir, &["compensate", "--blob", blob, "--targets", "t.csv", "--out", "c.csv"])
}

/// Item 11: `simulate` accepted what the importers refuse (`--noise 1e300`, effect sizes of 1e300,
/// `encoder_scale … scale=1e300`, `dead_zone … width=-1`) and wrote CSVs `cbd` could not read back.
/// Its arguments now obey the importers' limits, and what it writes, `fit` reads.
#[test]
fn simulate_writes_only_what_cbd_reads_back() {
    let dir = scratch("simulate-limits");
    for (args, needle) in [
        (vec!["--noise", "1e300"], "--noise must be a number in [0, 1e100]"),
        (vec!["--effect", "transmission:joint=1,harmonic=1,cos=1e300"], "cos = 1e300 is beyond ±1e100"),
        (vec!["--effect", "encoder_scale:joint=1,scale=1e300"], "scale = 1e300 is beyond ±1e100"),
        (vec!["--effect", "dead_zone:joint=1,width=-1"], "width = -1 must not be negative"),
        (vec!["--sampling", "uniform", "--count", "1000", "--effect", "thermal:dx=1e98"], "beyond the ±1e100 `cbd` reads back"),
    ] {
        let mut all = vec!["simulate", "--out", "s.csv"];
        all.extend(args);
        fails_with(&cbd(&dir, &all), &[needle]);
        assert!(!dir.join("s.csv").exists());
    }
    // At the edge of the limits the CSV reads back.
    succeeds(&cbd(&dir, &["simulate", "--grid", "4", "--noise", "1e90", "--out", "s.csv"]));
    let out = cbd(&dir, &["eval", "--blob", "none.blob", "--data", "s.csv"]);
    fails_with(&out, &["none.blob"]);
}

/// Item 12: `report --json` on `{}` exited 0 with an empty page; `compare --commanded foo` was
/// refused only after all six fits. Both are refused up front now.
#[test]
fn report_on_nothing_and_an_unknown_commanded_arm_are_refused_up_front() {
    let dir = scratch("report-commanded");
    write(&dir, "d.json", "{}");
    fails_with(&cbd(&dir, &["report", "--json", "d.json", "--out", "r.html"]), &["d.json: nothing to report"]);
    assert!(!dir.join("r.html").exists());
    let grid = rr_grid(&dir, "g4.csv", 4);
    let model = write(&dir, "rr.toml", PLANAR_RR_MODEL);
    let out = cbd(&dir, &["compare", "--model", &model, "--train", &grid, "--test", &grid, "--commanded", "foo"]);
    let err = fails_with(&out, &["--commanded", "foo"]);
    assert!(out.stdout.is_empty() && !err.contains("hyperparameters"), "the fits ran first:\n{}", String::from_utf8_lossy(&out.stdout));
    fails_with(
        &cbd(&dir, &["compare", "--model", &model, "--train", &grid, "--test", &grid, "--commanded", "six"]),
        &["--commanded six", "6 joints"],
    );
}

/// Item 2: under a memory limit below faer's matrix-multiply workspace (a thread-local buffer of
/// twice the L3 figure, 960 MiB on a large server) a 256-row fit aborted (`memory allocation of
/// 1006632960 bytes failed`), and at 1 GB rayon's global pool panicked: the check counted only the
/// N² matrices. It now counts each worker's workspace and stack and runs on one worker when two do
/// not fit: under every limit the fit succeeds or is refused up front (exit 1, one line naming
/// what fits or the limit to raise), never an abort, a panic or a signal.
#[test]
fn a_memory_limit_below_the_multiply_workspace_fits_or_refuses_up_front() {
    let dir = scratch("memory-limit-gemm");
    let grid = rr_grid(&dir, "grid256.csv", 16);
    let given = ["--joint-b", "0.001", "--gamma", "1", "--task-width", "10", "--task-gamma", "1", "--sigma", "1e-4", "--steps", "1"];
    let (mut fitted, mut refused) = (0, 0);
    for representation in ["auto", "kernel"] {
        for kib in [20_000u64, 100_000, 140_000, 160_000, 180_000, 220_000, 400_000, 1_000_000, 2_000_000] {
            let mut args = vec!["fit", "--data", grid.as_str(), "--out", "s.blob", "--quiet", "--representation", representation];
            args.extend(given);
            let out = cbd_limited(&dir, kib, &args);
            let err = stderr(&out);
            assert!(!err.contains("panicked") && !err.contains("memory allocation"), "ulimit -v {kib}: {err}");
            match out.status.code() {
                Some(0) => fitted += 1,
                Some(1) => {
                    refused += 1;
                    assert!(err.lines().count() == 1 && err.len() <= 1000, "ulimit -v {kib}: not one line:\n{err}");
                    assert!(
                        err.contains("raise the memory limit") || err.contains("rows fit") || err.contains("is the memory limit too low"),
                        "ulimit -v {kib}: {err}"
                    );
                }
                other => panic!("ulimit -v {kib} ({representation}): exit {other:?}\n{err}"),
            }
        }
    }
    // Both outcomes occur, so the scan crosses the check's threshold.
    assert!(fitted > 0 && refused > 0, "fitted {fitted}, refused {refused}");
}

/// Item 3: `cbd bench --sizes 16 --evidence-sizes 100000000 --no-ur5` unwrapped faer's AllocError
/// (no memory check in bench), and `--sizes 100000000` exited 1 with a panic's text. Every size is
/// now checked before the first fit, naming the flag and the size.
#[test]
fn bench_sizes_too_large_for_memory_are_refused_up_front() {
    let dir = scratch("bench-sizes");
    for (args, needles) in [
        (
            vec!["--sizes", "16", "--evidence-sizes", "100000000"],
            vec!["--evidence-sizes 100000000", "kernel ridge", "lower --evidence-sizes"],
        ),
        (vec!["--sizes", "100000000"], vec!["--sizes 100000000", "fitting 100000000 measurements", "lower --sizes"]),
        (vec!["--sizes", "16,99999999999999999"], vec!["99999999999999999", "not a perfect square"]),
    ] {
        let mut all = vec!["bench", "--no-ur5", "--json", "b.json"];
        all.extend(args);
        let out = cbd(&dir, &all);
        let err = fails_with(&out, &needles);
        assert!(err.lines().count() == 1 && out.stdout.is_empty(), "work ran first:\n{err}");
        assert!(!dir.join("b.json").exists());
    }
}

/// Messages (issue 27): a URDF origin made infinite by the unit conversion was blamed on a data
/// line; `diagnose` said "got 2" for a file of 3 rows (one held out); a model file without
/// `[measurements]` pointed to command-line flags that do not exist.
#[test]
fn messages_name_the_real_cause() {
    let dir = scratch("messages");
    write(
        &dir,
        "big.urdf",
        r#"<robot name="r"><link name="base"/><link name="l1"/><link name="tip"/>
<joint name="j1" type="revolute"><parent link="base"/><child link="l1"/><origin xyz="1e307 0 0" rpy="0 0 0"/><axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
<joint name="j2" type="fixed"><parent link="l1"/><child link="tip"/><origin xyz="0.5 0 0" rpy="0 0 0"/></joint></robot>"#,
    );
    let model = "length_unit = \"mm\"\nangle_unit = \"rad\"\n[urdf]\npath = \"big.urdf\"\nbase_link = \"base\"\ntip_link = \"tip\"\n[measurements]\njoints = [\"q1\"]\npositions = [\"x\", \"y\", \"z\"]\n";
    write(&dir, "big.toml", model);
    write(&dir, "one.csv", "q1,x,y,z\n0,1,0,0\n0.5,1,0.1,0\n1,1,0.2,0\n");
    let err = fails_with(
        &cbd(&dir, &["fit", "--model", "big.toml", "--data", "one.csv", "--out", "u.blob"]),
        &["big.urdf", "URDF joint 'j1'", "origin xyz has inf after the length unit's conversion"],
    );
    assert!(!err.contains("one.csv"), "{err}");
    let grid = rr_grid(&dir, "g4.csv", 4);
    let three = head(&dir, &grid, "g3.csv", 3);
    fails_with(&cbd(&dir, &["diagnose", "--data", &three]), &["got 2", "3 rows less 1 held out", "--test"]);
    let err = fails_with(&cbd(&dir, &["diagnose", "--data", &three, "--test", &three]), &["got 3"]);
    assert!(!err.contains("held out"), "{err}");
    write(&dir, "nomeas.toml", "length_unit = \"m\"\nangle_unit = \"rad\"\n[planar]\nlengths = [1.0, 0.5]\n");
    let err = fails_with(
        &cbd(&dir, &["fit", "--model", "nomeas.toml", "--data", &grid, "--out", "x.blob"]),
        &["nomeas.toml", "[measurements]", "joints = ["],
    );
    assert!(!err.contains("command line"), "{err}");
}

/// Item 2 as the issue saw it, on a server whose L3 figure made faer's workspace 960 MiB
/// (`memory allocation of 1006632960 bytes failed` under `ulimit -v 4000000`): here emulated by
/// binding a 480 MiB L3 size over sysfs in a user and mount namespace (`unshare -rm`), where faer's
/// multiply and the memory check read it. Since issue 48 the multiply's buffers follow the problem,
/// so the 256-row fit runs under every limit from 500 MB (it was refused there: "raise the memory
/// limit"). Skipped, saying so, where unprivileged namespaces are not allowed.
#[test]
fn a_large_server_cache_fits_from_500_mb_of_address_space() {
    let dir = scratch("memory-limit-large-l3");
    if !std::process::Command::new("unshare").args(["-rm", "true"]).status().is_ok_and(|s| s.success()) {
        eprintln!("skipped: no unprivileged user namespaces here (unshare -rm)");
        return;
    }
    let grid = rr_grid(&dir, "grid256.csv", 16);
    write(&dir, "l3", "491520K\n");
    let emulated = |kib: u64, args: &str| {
        let script = format!(
            "for f in /sys/devices/system/cpu/cpu*/cache/index3/size; do mount --bind l3 \"$f\" || exit 97; done; \
             ulimit -v {kib} && exec {CBD} {args}"
        );
        std::process::Command::new("unshare").args(["-rm", "sh", "-c", &script]).current_dir(&dir).output().unwrap()
    };
    let fit = |kib: u64| {
        emulated(
            kib,
            &format!(
                "fit --data {grid} --out s.blob --quiet --joint-b 0.001 --gamma 1 --task-width 10 --task-gamma 1 --sigma 1e-4 --steps 1"
            ),
        )
    };
    if fit(4_000_000).status.code() == Some(97) {
        eprintln!("skipped: no L3 cache in sysfs to emulate");
        return;
    }
    for kib in [500_000u64, 1_000_000, 2_000_000, 4_000_000] {
        let out = fit(kib);
        let err = stderr(&out);
        assert!(!err.contains("panicked") && !err.contains("memory allocation"), "ulimit -v {kib}: {err}");
        succeeds(&out);
    }
    // Item 3 there: bench's evidence sizes run after its other work, whose workspace the address
    // space already holds; checked once up front, they ran (a second check counted it twice).
    succeeds(&emulated(2_000_000, "bench --sizes 4 --evidence-sizes 9 --no-ur5 --json b.json"));
    assert!(dir.join("b.json").exists());
}

/// Found by the property harness (issue 27): `demo --grid 3000` (9e6 rows) and `demo
/// --test-points 1e11` aborted on allocation (exit 134). Both are refused up front, naming the flag.
#[test]
fn demo_sizes_too_large_for_memory_are_refused_up_front() {
    let dir = scratch("demo-sizes");
    for (args, needles) in [
        (vec!["--grid", "3000"], vec!["--grid 3000", "lower --grid"]),
        (vec!["--grid", "3000", "--hyperparameters", "evidence"], vec!["--grid 3000", "kernel ridge", "lower --grid"]),
        (vec!["--grid", "4", "--test-points", "100000000000"], vec!["--test-points 100000000000", "lower --test-points"]),
    ] {
        let mut all = vec!["demo", "--out", "d.blob"];
        all.extend(args);
        let out = cbd_limited(&dir, 400_000, &all);
        let err = fails_with(&out, &needles);
        assert!(err.lines().count() == 1, "{err}");
        assert!(!dir.join("d.blob").exists());
    }
}

/// `cbd eval ... | head -1`: a reader that closed its end of the pipe made `println!` panic
/// ("failed printing to stdout: Broken pipe"). Stdout is here a pipe whose read end is closed before
/// `cbd` starts, so every write fails with EPIPE: a quiet, successful exit (nothing on stderr but
/// what a normal run writes there), and the same run into an open pipe still prints the table.
#[test]
fn a_closed_stdout_pipe_is_a_quiet_exit() {
    let dir = scratch("broken-pipe");
    let model = ur5_model();
    let train = ur5_head(&dir, "train.csv", 60);
    succeeds(&cbd(&dir, &["fit", "--quiet", "--model", &model, "--data", &train, "--out", "m.blob"]));
    let eval = ["eval", "--model", model.as_str(), "--blob", "m.blob", "--data", train.as_str()];
    let (reader, writer) = std::io::pipe().unwrap();
    drop(reader);
    let out = std::process::Command::new(CBD).args(eval).current_dir(&dir).stdout(writer).output().unwrap();
    let err = stderr(&out);
    assert!(!err.contains("panicked") && !err.contains("Broken pipe"), "{err}");
    assert_eq!(out.status.code(), Some(0), "{err}");
    let open = succeeds(&cbd(&dir, &eval));
    assert!(!open.contains("panicked"));
    let printed = String::from_utf8_lossy(&cbd(&dir, &eval).stdout).into_owned();
    assert!(printed.lines().next().is_some_and(|l| l.starts_with("model")), "{printed}");
}

/// `cbd simulate ... 2>&1 | true`: a closed pipe on stderr made `eprintln!` panic (exit 101). Stderr is
/// here a pipe whose read end is closed before `cbd` starts: the run succeeds and writes its file; a
/// failing run still exits 1 (its `error:` line is lost, its status is not).
#[test]
fn a_closed_stderr_pipe_is_not_a_panic() {
    let dir = scratch("broken-stderr");
    let run = |args: &[&str]| {
        let (reader, writer) = std::io::pipe().unwrap();
        drop(reader);
        std::process::Command::new(CBD).args(args).current_dir(&dir).stderr(writer).output().unwrap()
    };
    let out = run(&["simulate", "--robot", "six", "--sampling", "uniform", "--count", "10", "--out", "six.csv"]);
    assert_eq!(out.status.code(), Some(0), "a run that writes to stderr");
    assert!(dir.join("six.csv").exists());
    let out = run(&["simulate", "--robot", "nine", "--out", "nine.csv"]);
    assert_eq!(out.status.code(), Some(1), "a refused run");
}

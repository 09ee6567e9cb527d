//! Issue 39 ("nothing wrong is accepted"): each of its 13 cases reconstructed through the real
//! binary. A wrong input exits 1 with one `error:` line naming the field; where the input is valid
//! the bad rows are flagged and counted in the summary, and no row flagged `ok` is wrong.

use crate::cli_support;

use cli_support::*;
use std::path::Path;

const TOOL_POINTS: &str = "0,0,0;100,0,0;50,86.60254037844386,0";

/// Exit 1 with exactly one `error:` line, the last, containing every needle; returns it.
#[track_caller]
fn refused(out: &std::process::Output, needles: &[&str]) -> String {
    let err = fails_with(out, needles);
    assert_eq!(err.lines().filter(|l| l.starts_with("error: ")).count(), 1, "{err}");
    assert!(err.lines().last().unwrap_or("").starts_with("error: "), "{err}");
    err
}

/// The UR5 model file with `from` replaced by `to` (once), written as `name`.
fn ur5_with(dir: &Path, name: &str, from: &str, to: &str) -> String {
    let text = std::fs::read_to_string(ur5_model()).unwrap();
    assert!(text.contains(from), "{from}");
    write(dir, name, text.replacen(from, to, 1))
}

/// The tool-points example model (points columns) with `from` replaced by `to`, as `name`.
fn points_model_with(dir: &Path, name: &str, from: &str, to: &str) -> String {
    let text = std::fs::read_to_string(examples().join("tool-points/six-points.toml")).unwrap();
    assert!(text.contains(from), "{from}");
    write(dir, name, text.replacen(from, to, 1))
}

/// 60 simulated six-joint rows and a blob fitted on them with the UR5 file (no search).
fn six_fixture(dir: &Path) -> (String, String) {
    succeeds(&cbd(
        dir,
        &["simulate", "--robot", "six", "--sampling", "uniform", "--count", "60", "--seed", "1", "--noise", "0.02", "--out", "six.csv"],
    ));
    succeeds(&fit_without_search(dir, &ur5_model(), "six.csv", "ur5.blob"));
    ("six.csv".into(), "ur5.blob".into())
}

/// 40 simulated poses at three tool points, a blob of them (six-points.toml, no search), and 20
/// target poses (their points and pose columns, noise-free).
fn points_fixture(dir: &Path) -> String {
    let sim = |count: &str, seed: &str, noise: &str, out: &str, pose: bool| {
        let mut args = vec!["simulate", "--robot", "six", "--sampling", "uniform", "--count", count, "--seed", seed, "--noise", noise];
        args.extend(["--tool-points", TOOL_POINTS, "--out", out]);
        if pose {
            args.push("--pose");
        }
        succeeds(&cbd(dir, &args));
    };
    sim("40", "1", "0.02", "points.csv", false);
    sim("20", "9", "0", "targets.csv", true);
    let model = examples().join("tool-points/six-points.toml");
    succeeds(&fit_without_search(dir, model.to_str().unwrap(), "points.csv", "points.blob"));
    "points.blob".into()
}

/// The rows of a CSV the CLI wrote: header and fields.
fn rows(dir: &Path, name: &str) -> (Vec<String>, Vec<Vec<String>>) {
    let text = std::fs::read_to_string(dir.join(name)).unwrap();
    let mut lines = text.lines().map(|l| l.split(',').map(str::to_string).collect::<Vec<_>>());
    (lines.next().unwrap(), lines.collect())
}

/// Every row flagged `ok` of a `cbd compensate --out` file holds its contract when read back as
/// measurements: `cbd eval` with the same model file (its joint map and limits: a value outside
/// them is refused) puts the calibrated tool within `within` of the target at every such row.
/// `targets` holds the target rows (their position columns) in order. Returns the ok count.
fn ok_rows_hold(dir: &Path, model: &str, blob: &str, commands: &str, targets: &str, within: f64) -> usize {
    let (header, commanded) = rows(dir, commands);
    let (target_header, target_rows) = rows(dir, targets);
    let flags = header.iter().position(|h| h == "flags").unwrap();
    let joints = header.iter().take_while(|h| !h.contains("residual")).count();
    let text = std::fs::read_to_string(dir.join(model)).unwrap();
    // The position columns the model file names, in the targets file.
    let wanted: Vec<usize> = target_header
        .iter()
        .enumerate()
        .filter(|(_, h)| text.contains(&format!("\"{h}\"")) && !h.starts_with('q'))
        .map(|(i, _)| i)
        .collect();
    let mut csv = header[..joints].join(",");
    for &c in &wanted {
        csv += &format!(",{}", target_header[c]);
    }
    csv.push('\n');
    let mut ok = 0;
    for (row, target) in commanded.iter().zip(&target_rows) {
        if row[flags] != "ok" {
            continue;
        }
        ok += 1;
        assert!(row[..joints].iter().all(|v| v.parse::<f64>().unwrap().is_finite()), "{row:?}");
        let values: Vec<&str> = row[..joints].iter().map(String::as_str).chain(wanted.iter().map(|&c| target[c].as_str())).collect();
        csv += &(values.join(",") + "\n");
    }
    if ok == 0 {
        return 0;
    }
    write(dir, "ok-rows.csv", csv);
    // The same model file without its `min_rows` (a few ok rows are enough to check).
    write(dir, "ok-model.toml", text.replace("min_rows = 10\n", ""));
    let out = cbd(dir, &["eval", "--model", "ok-model.toml", "--blob", blob, "--data", "ok-rows.csv", "--json", "ok-rows.json"]);
    succeeds(&out);
    let summary = json(&dir.join("ok-rows.json"));
    // A pose target is the tool frame (the least-squares frame of the calibrated points, which CbD
    // need not keep rigid); a position target is the point.
    let pose = &summary["pose"]["calibrated"];
    let (max, angle) = match pose["frame_position"]["max"].as_f64() {
        Some(origin) => (origin, pose["orientation_deg"]["max"].as_f64().unwrap()),
        None => (summary["calibrated"]["max"].as_f64().unwrap(), 0.0),
    };
    assert!(max <= within && angle <= 1e-6, "an `ok` row misses its target by {max:e} (orientation {angle:e}°)");
    ok
}

/// Case 1: a joint map with `scale = { q1 = 1e-320 }` passed and `compensate` wrote −inf flagged
/// `ok`; 1e-300 gave −8e301° `ok`; a coupling of condition 1e11 gave q6 = −2.4e10° `ok`. The map
/// is checked whole at load, and a valid but extreme coupling's rows are flagged outside the limits.
#[test]
fn case_01_joint_maps_are_checked_whole_and_commands_within_limits() {
    let dir = scratch("iv-01");
    let (six, blob) = six_fixture(&dir);
    let targets = "targets.csv";
    let text = std::fs::read_to_string(dir.join(&six)).unwrap();
    let mut t = String::from("x_mm,y_mm,z_mm\n");
    for line in text.lines().skip(1).take(20) {
        t += &(line.split(',').skip(6).collect::<Vec<_>>().join(",") + "\n");
    }
    write(&dir, targets, t);
    let map = |name: &str, table: &str| ur5_with(&dir, name, "min_rows = 10", &format!("min_rows = 10\n[measurements.joint_map]\n{table}"));
    for (name, table, needle) in [
        ("tiny.toml", "scale = { q1 = 1e-320 }", "condition number inf"),
        ("small.toml", "scale = { q1 = 1e-300 }", "condition number"),
        ("uniform.toml", "scale = { q1 = 1e-90, q2 = 1e-90, q3 = 1e-90, q4 = 1e-90, q5 = 1e-90, q6 = 1e-90 }", "its inverse"),
    ] {
        let model = map(name, table);
        refused(
            &cbd(&dir, &["compensate", "--model", &model, "--blob", &blob, "--targets", targets, "--out", "c.csv"]),
            &[name, "[measurements.joint_map]", needle],
        );
    }
    // Condition 4e11: accepted (within 1e12), but its inverse throws commands far outside ±360°.
    let coupled = map(
        "coupled.toml",
        "coupling = [[1, 0, 0, 0, 0, 0], [0, 1, 0, 0, 0, 0], [0, 0, 1, 0, 0, 0], [0, 0, 0, 1, 0, 0], [0, 0, 0, 0, 1, 1], [0, 0, 0, 0, 1, 1.00000000001]]",
    );
    let err = succeeds(&cbd(
        &dir,
        &["compensate", "--model", &coupled, "--blob", &blob, "--targets", targets, "--out", "c.csv", "--json", "c.json"],
    ));
    let summary = json(&dir.join("c.json"));
    let outside = summary["outside_limits"].as_u64().unwrap();
    assert!(outside > 0 && err.contains(&format!("{outside} outside the joint limits")), "{err}");
    assert!(!std::fs::read_to_string(dir.join("c.csv")).unwrap().contains("inf"));
    ok_rows_hold(&dir, &coupled, &blob, "c.csv", targets, 1e-6);
}

/// Case 2: pose compensation ignored `joint_limits` (q5 = 276° against ±180°, flagged `ok`).
/// Commands are turned into the limits by whole turns where that keeps the pose, and flagged
/// `outside_limits` otherwise; every `ok` row reads back within the limits and reaches its target.
#[test]
fn case_02_pose_commands_respect_joint_limits() {
    let dir = scratch("iv-02");
    let blob = points_fixture(&dir);
    let limits = "joint_limits = [[-180, 180], [-180, 180], [-180, 180], [-180, 180], [-180, 180], [-180, 180]]";
    let model = points_model_with(&dir, "limited.toml", "min_rows = 10", &format!("min_rows = 10\n{limits}"));
    let err = succeeds(&cbd(&dir, &["compensate", "--model", &model, "--blob", &blob, "--targets", "targets.csv", "--out", "c.csv"]));
    assert!(err.contains("outside the joint limits"), "{err}");
    let (header, commands) = rows(&dir, "c.csv");
    let flags = header.iter().position(|h| h == "flags").unwrap();
    for row in &commands {
        let inside = row[..6].iter().all(|v| v.parse::<f64>().unwrap().abs() <= 180.0);
        assert!(inside || row[flags].contains("outside_limits"), "{row:?}");
    }
    let ok = ok_rows_hold(&dir, &model, &blob, "c.csv", "targets.csv", 1e-6);
    assert!(ok >= 15, "{ok} of 20 ok");
}

/// Case 3: a blob and a model file that disagree (3 tool points against 1, and the reverse), and
/// crafted blobs (valid checksum) of 2 or 4 points that regroup the rows, were evaluated with exit 0.
#[test]
fn case_03_blob_and_model_file_must_agree() {
    let dir = scratch("iv-03");
    let (six, one) = six_fixture(&dir);
    let three = points_fixture(&dir);
    let points_model = examples().join("tool-points/six-points.toml");
    let points_model = points_model.to_str().unwrap();
    refused(
        &cbd(&dir, &["eval", "--model", &ur5_model(), "--blob", &three, "--data", &six]),
        &["points.blob: does not fit", "3 tool point"],
    );
    refused(&cbd(&dir, &["eval", "--model", points_model, "--blob", &one, "--data", "points.csv"]), &["ur5.blob: does not fit", "names 3"]);
    let pose_model = examples().join("tool-points/six-pose.toml");
    refused(
        &cbd(&dir, &["compensate", "--model", pose_model.to_str().unwrap(), "--blob", &one, "--targets", "targets.csv", "--out", "c.csv"]),
        &["ur5.blob: does not fit"],
    );
    // The blob's own framing: the tool points are its payload's tail (a count, then 3 f64 each),
    // followed in format 7 by the noise σ (one f64), which the edits keep in place.
    let bytes = std::fs::read(dir.join(&three)).unwrap();
    assert_eq!(reframe(&bytes, |_| {}), bytes, "the test's CRC is the blob's");
    let sigma_len = if u16::from_le_bytes([bytes[4], bytes[5]]) >= 7 { 8 } else { 0 };
    let edit_points = |p: &mut Vec<u8>, edit: &dyn Fn(&mut Vec<u8>)| {
        let sigma = p.split_off(p.len() - sigma_len);
        edit(p);
        p.extend(sigma);
    };
    let two = reframe(&bytes, |p| {
        edit_points(p, &|p| {
            let at = p.len() - 1 - 3 * 24;
            assert_eq!(p[at], 3);
            p[at] = 2;
            p.truncate(p.len() - 24);
        })
    });
    let four = reframe(&bytes, |p| {
        edit_points(p, &|p| {
            let at = p.len() - 1 - 3 * 24;
            p[at] = 4;
            p.extend([10.0f64, 20.0, 30.0].iter().flat_map(|v| v.to_le_bytes()));
        })
    });
    for (name, crafted) in [("two.blob", two), ("four.blob", four)] {
        write(&dir, name, crafted);
        refused(
            &cbd(&dir, &["eval", "--blob", name, "--model", points_model, "--data", "points.csv"]),
            &[name, "points (a pose's tool points at different configurations)"],
        );
    }
}

/// Case 4: `compare --commanded six` over a registered base reported 1000 of 1000 targets missed
/// by a metre with exit 0. Refused up front.
#[test]
fn case_04_commanded_table_refuses_a_registered_base() {
    let dir = scratch("iv-04");
    let (six, _) = six_fixture(&dir);
    let model = ur5_with(&dir, "tracker.toml", "base = { translation = [0, 0, 0], rpy = [0, 0, 0] }", "base = { register = true }");
    // Before any fit: seconds, not the minutes of the fits.
    refused(
        &cbd_within(&dir, 20, &["compare", "--model", &model, "--train", &six, "--test", &six, "--commanded", "six"]),
        &["--commanded", "register = true"],
    );
}

/// Case 5: fixed-length arrays took extra entries (NaN, 1e999 included) silently.
#[test]
fn case_05_fixed_length_arrays_are_read_exactly() {
    let dir = scratch("iv-05");
    let (six, blob) = six_fixture(&dir);
    let eval = |model: &str| cbd(&dir, &["eval", "--model", model, "--blob", &blob, "--data", &six]);
    let base = "base = { translation = [0, 0, 0], rpy = [0, 0, 0] }";
    for (from, to, field) in [
        ("tool = { translation = [0, 0, 31] }", "tool = { translation = [0, 0, 31, 99] }", "tool.translation"),
        ("tool = { translation = [0, 0, 31] }", "tool = { translation = [0, 0, 31, nan] }", "tool.translation"),
        (base, "base = { translation = [0, 0, 0], rpy = [0, 0, 0, 4] }", "base.rpy"),
        (base, "base = { rotation = [[1, 0, 0], [0, 1, 0], [0, 0, 1], [0, 0, 0]] }", "base.rotation"),
        (base, "base = { rotation = [[1, 0, 0], [0, 1, 0], [0, 0, 1], [0, 0, 0], [1, 1, 1]] }", "base.rotation"),
        (base, "base = { rotation = [[1, 0, 0, 0], [0, 1, 0], [0, 0, 1]] }", "base.rotation"),
        ("min_rows = 10", "min_rows = 10\njoint_limits = [[-1, 1, 3], [-1, 1], [-1, 1], [-1, 1], [-1, 1], [-1, 1]]", "joint_limits"),
    ] {
        let model = ur5_with(&dir, "bad.toml", from, to);
        refused(&eval(&model), &["bad.toml", field, "expected an array of exactly"]);
    }
    let model = points_model_with(&dir, "bad.toml", "[50, 86.60254037844386, 0]", "[50, 86.60254037844386, 0, 1e999]");
    refused(&eval(&model), &["bad.toml", "tool.points"]);
    let planar = PLANAR_RR_MODEL.replace("lengths = [1.0, 0.5]", "lengths = [1.0, 0.5]\nbase = [0.1, 0.2, nan]");
    write(&dir, "planar.toml", planar);
    refused(
        &cbd(&dir, &["plan", "--model", "planar.toml", "--count", "2", "--out", "p.csv"]),
        &["planar.toml", "[planar] base", "exactly 2"],
    );
}

/// Case 6: three coincident target points, collinear ones, or a triangle twice the tool's came
/// back `ok` with an arbitrary orientation. Flagged `degenerate_target`, counted, exit 0.
#[test]
fn case_06_degenerate_pose_targets_are_flagged() {
    let dir = scratch("iv-06");
    let blob = points_fixture(&dir);
    let (header, targets) = rows(&dir, "targets.csv");
    let point = |r: &[String], j: usize| -> [f64; 3] { std::array::from_fn(|c| r[6 + 3 * j + c].parse().unwrap()) };
    let (p1, p2, p3) = (point(&targets[0], 0), point(&targets[0], 1), point(&targets[0], 2));
    let mid: [f64; 3] = std::array::from_fn(|c| (p1[c] + p2[c]) / 2.0);
    let twice = |p: [f64; 3]| -> [f64; 3] { std::array::from_fn(|c| p1[c] + 2.0 * (p[c] - p1[c])) };
    let mut text = header[6..15].join(",") + "\n";
    for set in [[p1, p1, p1], [p1, p2, mid], [p1, twice(p2), twice(p3)], [p1, p2, p3]] {
        text += &(set.iter().flatten().map(|v| format!("{v:?}")).collect::<Vec<_>>().join(",") + "\n");
    }
    write(&dir, "odd.csv", text);
    let model = examples().join("tool-points/six-points.toml");
    let err = succeeds(&cbd(
        &dir,
        &["compensate", "--model", model.to_str().unwrap(), "--blob", &blob, "--targets", "odd.csv", "--out", "c.csv"],
    ));
    assert!(err.contains("3 degenerate targets"), "{err}");
    let (header, commands) = rows(&dir, "c.csv");
    let flags: Vec<&str> = commands.iter().map(|r| r[header.len() - 1].as_str()).collect();
    assert!(flags[..3].iter().all(|f| f.contains("degenerate_target")), "{flags:?}");
    assert_eq!(flags[3], "ok");
}

/// Case 7: mirrored or collinear tracker data with `register = true` ran for a minute or more
/// (and the warning asked for `register = true`, which was set). Refused up front with the reason;
/// a fit over far, mirrored data with a declared base ends within a bound.
#[test]
fn case_07_degenerate_registration_is_refused_and_fits_are_bounded() {
    let dir = scratch("iv-07");
    let mut args = vec!["simulate", "--robot", "six", "--sampling", "uniform", "--count", "60", "--seed", "1", "--noise", "0.02"];
    args.extend(["--tracker-frame", "2500,-3000,800;1,-2,3,30", "--out", "tracker.csv"]);
    succeeds(&cbd(&dir, &args));
    let text = std::fs::read_to_string(dir.join("tracker.csv")).unwrap();
    let mut lines = text.lines();
    let mut mirrored = lines.next().unwrap().to_string() + "\n";
    let mut line = mirrored.clone();
    for (k, l) in lines.enumerate() {
        let mut f: Vec<String> = l.split(',').map(str::to_string).collect();
        f[6] = format!("{:?}", -f[6].parse::<f64>().unwrap());
        mirrored += &(f.join(",") + "\n");
        (f[6], f[7], f[8]) = (format!("{}", 10 * k), format!("{}", 5 * k), format!("{}", 2 * k));
        line += &(f.join(",") + "\n");
    }
    write(&dir, "mirrored.csv", mirrored);
    write(&dir, "line.csv", line);
    let tracker = ur5_with(&dir, "tracker.toml", "base = { translation = [0, 0, 0], rpy = [0, 0, 0] }", "base = { register = true }");
    // A tracker 1e50 mm away: f64 keeps none of the arm's extent (the registration said "RMS → 0").
    let last = args.len() - 1;
    (args[last - 2], args[last]) = ("1e50,0,0;0,0,1,10", "far.csv");
    succeeds(&cbd(&dir, &args));
    for (data, needle) in [("mirrored.csv", "mirror image"), ("line.csv", "lie on one line"), ("far.csv", "lost to rounding")] {
        refused(
            &cbd_within(&dir, 20, &["fit", "--model", &tracker, "--data", data, "--out", "x.blob"]),
            &[data, "cannot register the base", needle],
        );
    }
    // Declared base: fitted (far from the model, warned about), in bounded time.
    let err = succeeds(&cbd_within(&dir, 60, &["fit", "--model", &ur5_model(), "--data", "mirrored.csv", "--out", "m.blob"]));
    assert!(err.contains("warning: mirrored.csv: the nominal model is"), "{err}");
}

/// A UR5 as a URDF (metres), its joints named like a vendor's.
const UR5_URDF: &str = r#"<?xml version="1.0"?>
<robot name="ur5">
  <link name="base"/><link name="l1"/><link name="l2"/><link name="l3"/><link name="l4"/><link name="l5"/><link name="l6"/><link name="tool"/>
  <joint name="shoulder_pan" type="revolute"><parent link="base"/><child link="l1"/><origin xyz="0 0 0"/><axis xyz="0 0 1"/><limit lower="-6.3" upper="6.3" effort="1" velocity="1"/></joint>
  <joint name="shoulder_lift" type="revolute"><parent link="l1"/><child link="l2"/><origin xyz="0 0 0.089159" rpy="1.5707963267948966 0 0"/><axis xyz="0 0 1"/><limit lower="-6.3" upper="6.3" effort="1" velocity="1"/></joint>
  <joint name="elbow" type="revolute"><parent link="l2"/><child link="l3"/><origin xyz="-0.425 0 0"/><axis xyz="0 0 1"/><limit lower="-6.3" upper="6.3" effort="1" velocity="1"/></joint>
  <joint name="wrist_1" type="revolute"><parent link="l3"/><child link="l4"/><origin xyz="-0.39225 0 0"/><axis xyz="0 0 1"/><limit lower="-6.3" upper="6.3" effort="1" velocity="1"/></joint>
  <joint name="wrist_2" type="revolute"><parent link="l4"/><child link="l5"/><origin xyz="0 0 0.10915" rpy="1.5707963267948966 0 0"/><axis xyz="0 0 1"/><limit lower="-6.3" upper="6.3" effort="1" velocity="1"/></joint>
  <joint name="wrist_3" type="revolute"><parent link="l5"/><child link="l6"/><origin xyz="0 0 0.09465" rpy="-1.5707963267948966 0 0"/><axis xyz="0 0 1"/><limit lower="-6.3" upper="6.3" effort="1" velocity="1"/></joint>
  <joint name="flange" type="fixed"><parent link="l6"/><child link="tool"/><origin xyz="0 0 0.1133"/></joint>
</robot>
"#;

/// Case 8: `diagnose --write-model` on a URDF model with a joint map failed ("internal: the written
/// model file does not read back … no model joint named 'j2'"): the DH table renames the joints.
#[test]
fn case_08_a_urdf_models_joint_map_is_written_back() {
    let dir = scratch("iv-08");
    let (six, _) = six_fixture(&dir);
    write(&dir, "ur5.urdf", UR5_URDF);
    let model = write(
        &dir,
        "urdf.toml",
        "length_unit = \"mm\"\nangle_unit = \"deg\"\n[urdf]\npath = \"ur5.urdf\"\nbase_link = \"base\"\ntip_link = \"tool\"\n\
         [measurements]\njoints = [\"q1_deg\", \"q2_deg\", \"q3_deg\", \"q4_deg\", \"q5_deg\", \"q6_deg\"]\npositions = [\"x_mm\", \"y_mm\", \"z_mm\"]\n\
         [measurements.joint_map]\nsign = { elbow = 1 }\noffset = { wrist_3 = 0 }\n",
    );
    succeeds(&cbd(&dir, &["diagnose", "--no-cbd", "--model", &model, "--data", &six, "--write-model", "written.toml"]));
    let written = std::fs::read_to_string(dir.join("written.toml")).unwrap();
    assert!(written.contains("\"q3\" = 1.0") && written.contains("\"q6\" = 0.0"), "{written}");
    // The written file is a model file like any other.
    succeeds(&fit_without_search(&dir, "written.toml", &six, "w.blob"));
    // The URDF is an input: an output on it is refused before any work.
    refused(
        &cbd(&dir, &["diagnose", "--no-cbd", "--model", &model, "--data", &six, "--json", "ur5.urdf"]),
        &["ur5.urdf", "is also an input"],
    );
    assert_eq!(std::fs::read_to_string(dir.join("ur5.urdf")).unwrap(), UR5_URDF);
}

/// Case 9: `joint_limits` of ±1e300 were accepted (the ±1e100 rule) and `cbd plan` wrote poses at
/// 8.6e299°.
#[test]
fn case_09_joint_limits_obey_the_magnitude_rule() {
    let dir = scratch("iv-09");
    let limits = "joint_limits = [[-1e300, 1e300], [-180, 0], [-160, 160], [-180, 180], [-180, 180], [-180, 180]]";
    let text = std::fs::read_to_string(ur5_dir().join("simulated-six.toml")).unwrap();
    let at = text.find("joint_limits").unwrap();
    write(&dir, "huge.toml", format!("{}{limits}\n", &text[..at]));
    let err =
        refused(&cbd(&dir, &["plan", "--model", "huge.toml", "--count", "3", "--out", "p.csv"]), &["huge.toml", "joint_limits", "1e300"]);
    assert!(err.len() < 300, "{err}");
    assert!(!dir.join("p.csv").exists());
}

/// Case 10: a column named twice in `[measurements]` was read twice; `compensate` wrote two
/// `q5_deg` columns with different values.
#[test]
fn case_10_no_column_is_named_twice() {
    let dir = scratch("iv-10");
    let (six, blob) = six_fixture(&dir);
    let joints = "joints = [\"q1_deg\", \"q2_deg\", \"q3_deg\", \"q4_deg\", \"q5_deg\", \"q6_deg\"]";
    for (from, to, needle) in [
        (
            joints,
            "joints = [\"q1_deg\", \"q2_deg\", \"q3_deg\", \"q4_deg\", \"q5_deg\", \"q5_deg\"]",
            "joints[6]: column 'q5_deg' is already joints[5]",
        ),
        (
            "positions = [\"x_mm\", \"y_mm\", \"z_mm\"]",
            "positions = [\"x_mm\", \"y_mm\", \"q5_deg\"]",
            "positions[3]: column 'q5_deg' is already joints[5]",
        ),
    ] {
        let model = ur5_with(&dir, "twice.toml", from, to);
        refused(&cbd(&dir, &["eval", "--model", &model, "--blob", &blob, "--data", &six]), &["twice.toml", "[measurements]", needle]);
    }
    let model = points_model_with(
        &dir,
        "twice.toml",
        "positions = [\"x1_mm\", \"y1_mm\", \"z1_mm\", \"x2_mm\", \"y2_mm\", \"z2_mm\", \"x3_mm\", \"y3_mm\", \"z3_mm\"]",
        "positions = [\"x1_mm\", \"y1_mm\", \"z1_mm\", \"x1_mm\", \"y1_mm\", \"z1_mm\", \"x1_mm\", \"y1_mm\", \"z1_mm\"]",
    );
    refused(
        &cbd(&dir, &["eval", "--model", &model, "--blob", &blob, "--data", &six]),
        &["twice.toml", "positions[4]: column 'x1_mm' is already positions[1]"],
    );
}

/// Case 11: `cbd plan` with `--data` of 3–5 rows predicted 2e-9 mm though the geometric group was
/// not identified; a prismatic joint far out printed "NaN mm".
#[test]
fn case_11_plan_predicts_only_what_the_data_support() {
    let dir = scratch("iv-11");
    let text = std::fs::read_to_string(ur5_dir().join("simulated-six.toml")).unwrap();
    write(&dir, "six.toml", text.replace("min_rows = 10\n", ""));
    for rows in [3, 5] {
        let mut args = vec!["simulate", "--robot", "six", "--sampling", "uniform", "--seed", "3", "--noise", "0.02", "--out", "few.csv"];
        let count = rows.to_string();
        args.extend(["--count", &count]);
        succeeds(&cbd(&dir, &args));
        let plan = ["plan", "--model", "six.toml", "--data", "few.csv", "--count", "30", "--candidates", "300", "--workspace", "16"];
        let err = succeeds(&cbd(&dir, &[&plan[..], &["--out", "p.csv", "--json", "p.json"]].concat()));
        assert!(err.contains(&format!("{rows} poses do not identify the geometric group (23 parameters")), "{err}");
        let plan = json(&dir.join("p.json"));
        assert_eq!(plan["prior"], "stated");
        // Predictions from the stated prior (3e-4 of the reach): tenths of a millimetre, not 1e-9.
        let last = plan["learning_curve"].as_array().unwrap().last().unwrap()["predicted_rms"].as_f64().unwrap();
        assert!(last > 1e-3, "{last}");
    }
    let prismatic = "length_unit = \"mm\"\nangle_unit = \"deg\"\n[chain]\nconvention = \"standard\"\n\
        joints = [ { a = 300, alpha = 0, d = 0 }, { a = 200, alpha = 0, d = 0, kind = \"prismatic\" }, { a = 100, alpha = 0, d = 0 } ]\n\
        [measurements]\njoints = [\"q1\", \"q2\", \"q3\"]\npositions = [\"x\", \"y\", \"z\"]\njoint_limits = [[-170, 170], [0, 500], [-170, 170]]\n";
    write(&dir, "far.toml", format!("{prismatic}[measurements.joint_map]\noffset = {{ q2 = 1e99 }}\n"));
    refused(
        &cbd(&dir, &["plan", "--model", "far.toml", "--count", "5", "--out", "p.csv"]),
        &["far.toml", "[measurements.joint_map]", "offset"],
    );
    write(&dir, "long.toml", prismatic.replace("{ a = 200, alpha = 0, d = 0,", "{ a = 200, alpha = 0, d = 1e99,"));
    let out = cbd(&dir, &["plan", "--model", "long.toml", "--count", "5", "--candidates", "300", "--workspace", "16", "--out", "p.csv"]);
    assert!(!stderr(&out).contains("NaN") && matches!(out.status.code(), Some(0) | Some(1)), "{}", stderr(&out));
    refused(&cbd(&dir, &["plan", "--model", "six.toml", "--count", "100000", "--out", "p.csv"]), &["--count 100000", "candidate"]);
}

/// Case 12: `simulate --pose` with collinear tool points wrote arbitrary quaternions; duplicate
/// points and a point at 1e10 mm were taken by `--tool-points` though model files refuse them.
#[test]
fn case_12_simulated_tool_points_obey_the_model_files_rules() {
    let dir = scratch("iv-12");
    let sim = |points: &str, pose: bool| {
        let mut args =
            vec!["simulate", "--robot", "six", "--sampling", "uniform", "--count", "5", "--tool-points", points, "--out", "s.csv"];
        if pose {
            args.push("--pose");
        }
        cbd(&dir, &args)
    };
    refused(&sim("0,0,0;100,0,0;200,0,0", true), &["--pose", "on a line"]);
    refused(&sim("0,0,0;0,0,0;1,2,3", false), &["--tool-points", "points 1 and 2 are the same point"]);
    refused(&sim("0,0,0;1e10,0,0;0,5,0", false), &["--tool-points", "point 2: 1e10"]);
    refused(&sim("0,0,0;100,0,0;0,100,0,7", false), &["--tool-points", "point 3 has 4 coordinates"]);
    succeeds(&sim(TOOL_POINTS, true));
    // A message suggests only what applies: `simulate --poses` reads no model file's `joint_limits`.
    write(&dir, "far.csv", "q1,q2\n9,0.1\n");
    let err = refused(&cbd(&dir, &["simulate", "--poses", "far.csv", "--out", "s.csv"]), &["far.csv:2", "outside the joint's range"]);
    assert!(!err.contains("joint_limits"), "{err}");
}

/// Case 13: crafted blobs (valid checksum) with a non-orthonormal or mirrored tool rotation
/// evaluated to 1.3e24 mm with exit 0, and compensation "reached" with such a tool.
#[test]
fn case_13_a_blobs_rotations_must_be_rotations() {
    let dir = scratch("iv-13");
    let (six, _) = six_fixture(&dir);
    // A tool turned by a known angle, so that its rotation's entries can be found in the payload.
    let (c, s) = (0.3f64.cos(), 0.3f64.sin());
    let turned = ur5_with(
        &dir,
        "turned.toml",
        "tool = { translation = [0, 0, 31] }",
        &format!("tool = {{ translation = [0, 0, 31], rotation = [[{c:?}, {:?}, 0], [{s:?}, {c:?}, 0], [0, 0, 1]] }}", -s),
    );
    succeeds(&fit_without_search(&dir, &turned, &six, "turned.blob"));
    let bytes = std::fs::read(dir.join("turned.blob")).unwrap();
    let scaled = reframe(&bytes, |p| {
        replace_f64(p, c, c * 1.001, 0);
        replace_f64(p, c, c * 1.001, 0);
    });
    let mirrored = reframe(&bytes, |p| {
        replace_f64(p, s, -s, 0);
        replace_f64(p, c, -c, 1);
    });
    write(&dir, "t.csv", "x_mm,y_mm,z_mm\n300,200,500\n");
    for (name, crafted) in [("scaled.blob", scaled), ("mirrored.blob", mirrored)] {
        write(&dir, name, crafted);
        refused(&cbd(&dir, &["eval", "--model", &turned, "--blob", name, "--data", &six]), &[name, "nominal.tool.rotation"]);
        refused(
            &cbd(&dir, &["compensate", "--model", &turned, "--blob", name, "--targets", "t.csv", "--out", "c.csv"]),
            &[name, "nominal.tool.rotation"],
        );
    }
}

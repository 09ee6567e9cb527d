//! Issue 26 item 3: a joint mapping in the model file (`[measurements.joint_map]`) against the
//! same data converted by hand — the FANUC convention, q3 = −(J3 + J2) and J4–J6 reversed.

use crate::cli_support;

use cbd_trainer::data::csv_import::read_measurements;
use cbd_trainer::data::model_file::{load_model_file, parse_model_file, write_model_file};
use cli_support::*;
use std::path::Path;

const MAPPING: &str = "\n[measurements.joint_map]\nsign = { q3 = -1, q4 = -1, q5 = -1, q6 = -1 }\n\
coupling = [[1, 0, 0, 0, 0, 0], [0, 1, 0, 0, 0, 0], [0, 1, 1, 0, 0, 0], [0, 0, 0, 1, 0, 0], [0, 0, 0, 0, 1, 0], [0, 0, 0, 0, 0, 1]]\n";

/// The UR5 example's model file with other joint columns (and `extra` appended).
fn ur5_with_columns(columns: &[&str], extra: &str) -> String {
    let text = std::fs::read_to_string(ur5_model()).unwrap();
    let names: Vec<String> = columns.iter().map(|c| format!("\"{c}\"")).collect();
    let text = text.replace(
        "joints = [\"q1_deg\", \"q2_deg\", \"q3_deg\", \"q4_deg\", \"q5_deg\", \"q6_deg\"]",
        &format!("joints = [{}]", names.join(", ")),
    );
    assert!(text.contains(columns[0]));
    text + extra
}

/// The first `rows` rows of the UR5 training file as (model joints in degrees, position text).
fn ur5_rows(rows: usize) -> Vec<([f64; 6], String)> {
    let text = std::fs::read_to_string(ur5_dir().join("train.csv")).unwrap();
    text.lines()
        .skip(1)
        .take(rows)
        .map(|line| {
            let fields: Vec<&str> = line.split(',').collect();
            let q: [f64; 6] = std::array::from_fn(|k| fields[k].parse().unwrap());
            (q, fields[6..].join(","))
        })
        .collect()
}

/// Writes the controller's file (J1..J6: J3 = −q3 − J2, J4..J6 = −q) and the hand-converted one
/// (h1..h6 = the FANUC formula applied to those J in floating point).
fn controller_and_hand_files(dir: &Path, rows: usize) {
    let (mut controller, mut hand) =
        (String::from("J1,J2,J3,J4,J5,J6,x_mm,y_mm,z_mm\n"), String::from("h1,h2,h3,h4,h5,h6,x_mm,y_mm,z_mm\n"));
    for (q, position) in ur5_rows(rows) {
        let j = [q[0], q[1], -q[2] - q[1], -q[3], -q[4], -q[5]];
        let h = [j[0], j[1], -(j[2] + j[1]), -j[3], -j[4], -j[5]];
        let line = |v: &[f64; 6]| v.iter().map(|x| format!("{x:?}")).collect::<Vec<_>>().join(",") + "," + &position + "\n";
        controller += &line(&j);
        hand += &line(&h);
    }
    write(dir, "controller.csv", controller);
    write(dir, "hand.csv", hand);
    write(dir, "fanuc.toml", ur5_with_columns(&["J1", "J2", "J3", "J4", "J5", "J6"], MAPPING));
    write(dir, "hand.toml", ur5_with_columns(&["h1", "h2", "h3", "h4", "h5", "h6"], ""));
}

#[test]
fn fanuc_coupling_in_the_model_file_reproduces_the_hand_converted_columns_bit_for_bit() {
    let dir = scratch("joint-map-fanuc");
    controller_and_hand_files(&dir, 200);
    let fanuc = load_model_file(dir.join("fanuc.toml")).unwrap();
    let hand = load_model_file(dir.join("hand.toml")).unwrap();
    let mapped = read_measurements(dir.join("controller.csv"), &fanuc.column_spec().unwrap()).unwrap().measurements;
    let by_hand = read_measurements(dir.join("hand.csv"), &hand.column_spec().unwrap()).unwrap().measurements;
    assert_eq!(mapped.len(), 200);
    let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    assert_eq!(bits(&mapped.joints), bits(&by_hand.joints));
    assert_eq!(bits(&mapped.positions), bits(&by_hand.positions));
    // Not the identity: the controller's own columns differ from the model's joints.
    let raw =
        read_measurements(dir.join("controller.csv"), &fanuc.column_spec_with(fanuc.measurements.as_ref().unwrap().joints.clone(), vec![]))
            .unwrap();
    assert_ne!(bits(&raw.measurements.joints), bits(&by_hand.joints));

    // The mapping round-trips through a written model file.
    let written = write_model_file(&fanuc, "test");
    let back = parse_model_file(&written, &dir.join("fanuc.toml")).unwrap_or_else(|e| panic!("{e}\n{written}"));
    assert_eq!(back.measurements, fanuc.measurements);
    assert_eq!(back.joint_map, fanuc.joint_map);
    assert_eq!(write_model_file(&back, "test"), written);

    // The CLI reads it the same way: eval of one blob on both files gives the same figures.
    let fit_rows = head(&dir, "hand.csv", "hand-40.csv", 40);
    let out = fit_without_search(&dir, "hand.toml", &fit_rows, "arm.blob");
    succeeds(&out);
    for (model, data, json) in [("fanuc.toml", "controller.csv", "a.json"), ("hand.toml", "hand.csv", "b.json")] {
        succeeds(&cbd(&dir, &["eval", "--model", model, "--blob", "arm.blob", "--data", data, "--json", json]));
    }
    let (a, b) = (std::fs::read_to_string(dir.join("a.json")).unwrap(), std::fs::read_to_string(dir.join("b.json")).unwrap());
    assert_eq!(a, b);

    // compensate maps its commands back to the controller's values: the hand file's commands,
    // converted to J by the inverse formula, equal the mapped file's within rounding.
    let targets: String = std::iter::once("x_mm,y_mm,z_mm\n".to_string()).chain(ur5_rows(20).into_iter().map(|(_, p)| p + "\n")).collect();
    write(&dir, "targets.csv", targets);
    let seeds = |names: &str, from: &str| {
        let text = std::fs::read_to_string(dir.join(from)).unwrap();
        let rows: Vec<String> = text.lines().skip(1).take(20).map(|l| l.split(',').take(6).collect::<Vec<_>>().join(",")).collect();
        format!("{names}\n{}\n", rows.join("\n"))
    };
    write(&dir, "seeds-j.csv", seeds("J1,J2,J3,J4,J5,J6", "controller.csv"));
    write(&dir, "seeds-h.csv", seeds("h1,h2,h3,h4,h5,h6", "hand.csv"));
    for (model, seeds, out) in [("fanuc.toml", "seeds-j.csv", "cj.csv"), ("hand.toml", "seeds-h.csv", "ch.csv")] {
        let args = ["compensate", "--model", model, "--blob", "arm.blob", "--targets", "targets.csv", "--seeds", seeds, "--out", out];
        succeeds(&cbd(&dir, &args));
    }
    let rows = |name: &str| -> Vec<Vec<f64>> {
        let text = std::fs::read_to_string(dir.join(name)).unwrap();
        text.lines().skip(1).map(|l| l.split(',').take(7).map(|v| v.parse().unwrap()).collect()).collect()
    };
    let (cj, ch) = (rows("cj.csv"), rows("ch.csv"));
    assert_eq!(cj.len(), 20);
    for (j, h) in cj.iter().zip(&ch) {
        // h = model joints (degrees): J = (h1, h2, −h3 − h2, −h4, −h5, −h6).
        let want = [h[0], h[1], -h[2] - h[1], -h[3], -h[4], -h[5]];
        for k in 0..6 {
            assert!((j[k] - want[k]).abs() < 1e-9, "{j:?} vs {want:?}");
        }
        // The residual is the calibrated model's at the command as written and read back: the
        // coupling's inverse rounds the written columns differently from the hand-converted file's
        // (an ulp of the joints), so the two agree to rounding, both far inside the tolerance.
        assert!(j[6] <= 1e-9 && h[6] <= 1e-9 && (j[6] - h[6]).abs() <= 1e-12, "residuals {} and {}", j[6], h[6]);
    }
}

#[test]
fn a_bad_joint_map_is_an_error_naming_the_field() {
    let dir = scratch("joint-map-errors");
    let data = ur5_head(&dir, "train.csv", 20);
    let columns = ["q1_deg", "q2_deg", "q3_deg", "q4_deg", "q5_deg", "q6_deg"];
    let cases = [
        ("sign = { q9 = -1 }", "[measurements.joint_map] sign: no model joint named 'q9'"),
        ("scale = { q2 = 0.0 }", "[measurements.joint_map] scale: q2 = 0: needs a finite, non-zero factor"),
        ("coupling = [[1, 0], [0, 1]]", "[measurements.joint_map] coupling: needs 6 rows of 6 entries"),
        (
            "coupling = [[1, 0, 0, 0, 0, 0], [0, 1, 0, 0, 0, 0], [0, 1, 0, 0, 0, 0], [0, 0, 0, 1, 0, 0], [0, 0, 0, 0, 1, 0], [0, 0, 0, 0, 0, 1]]",
            "[measurements.joint_map] coupling: the matrix is singular",
        ),
        ("sign = { q1 = -1 }\nskew = 3", "skew"),
    ];
    for (k, (entry, needle)) in cases.iter().enumerate() {
        let name = format!("bad{k}.toml");
        write(&dir, &name, ur5_with_columns(&columns, &format!("\n[measurements.joint_map]\n{entry}\n")));
        fails_with(&cbd(&dir, &["fit", "--model", &name, "--data", &data, "--out", "x.blob"]), &[&name, needle]);
    }
}

//! Issue 26 item 6: a `[planar]` model file holds base x, y, yaw and joint offsets, so
//! `cbd diagnose --write-model` works on a planar arm whose base and offsets it corrects, and the
//! written file's nominal (`cbd eval`) is the diagnosed "nominal + effects" row.

use crate::cli_support;

use cbd_protocol::Effect;
use cbd_trainer::simulate::effects::EffectArm;
use cbd_trainer::simulate::rr::planar_arm;
use cbd_trainer::simulate::{configurations, Sampling};
use cli_support::*;

fn csv(data: &cbd_trainer::data::Measurements) -> String {
    let mut out = String::from("q1,q2,x,y\n");
    for i in 0..data.len() {
        let row: Vec<String> = data.joints(i).iter().chain(data.position(i)).map(|v| format!("{v:?}")).collect();
        out += &(row.join(",") + "\n");
    }
    out
}

fn json(dir: &std::path::Path, name: &str) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(dir.join(name)).unwrap()).unwrap()
}

#[test]
fn diagnose_writes_a_planar_file_whose_nominal_is_the_diagnosed_effects_row() {
    let dir = scratch("planar-frame");
    // Base moved by (3, −2) cm and turned by 0.01 rad, joint offsets 0.008 and −0.012 rad,
    // lengths 1.03 and 0.48 m, a second harmonic on joint 2, 0.1 mm noise.
    let arm = EffectArm::new(planar_arm(&[1.03, 0.48], [0.03, -0.02], 0.01, &[0.008, -0.012])).with(Effect::Transmission {
        joint: 1,
        harmonic: 2,
        cos: 2e-3,
        sin: -1e-3,
    });
    let train = arm.measure_planar(&configurations(Sampling::Uniform { count: 300, seed: 1 }, 2), 1e-4, 1);
    let test = arm.measure_planar(&configurations(Sampling::Uniform { count: 300, seed: 2 }, 2), 1e-4, 2);
    write(&dir, "train.csv", csv(&train));
    write(&dir, "test.csv", csv(&test));
    // The starting file already has a frame: the diagnosed one composes with it.
    let model =
        PLANAR_RR_MODEL.replace("lengths = [1.0, 0.5]", "lengths = [1.0, 0.5]\nbase = [0.01, 0.0]\nyaw = -0.004\noffsets = [0.0, 0.003]");
    write(&dir, "rr.toml", model);
    let args = ["diagnose", "--no-cbd", "--model", "rr.toml", "--data", "train.csv", "--test", "test.csv"];
    let out = cbd(&dir, &[&args[..], &["--write-model", "rr-effects.toml", "--json", "d.json"]].concat());
    succeeds(&out);
    let written = std::fs::read_to_string(dir.join("rr-effects.toml")).unwrap();
    assert!(
        written.contains("[planar]") && written.contains("base = [") && written.contains("yaw = ") && written.contains("offsets = ["),
        "{written}"
    );

    // Any blob will do for eval's nominal row.
    succeeds(&fit_without_search(&dir, "rr-effects.toml", "train.csv", "rr.blob"));
    succeeds(&cbd(&dir, &["eval", "--model", "rr-effects.toml", "--blob", "rr.blob", "--data", "test.csv", "--json", "e.json"]));
    let (d, e) = (json(&dir, "d.json"), json(&dir, "e.json"));
    let row = &d["held_out"]["nominal + effects"];
    let nominal_before = d["held_out"]["nominal"]["mean"].as_f64().unwrap();
    for key in ["mean", "median", "p99", "max"] {
        let (want, got) = (row[key].as_f64().unwrap(), e["nominal"][key].as_f64().unwrap());
        assert!((want - got).abs() <= 1e-9 * want, "{key}: diagnose {want:e}, eval {got:e}");
    }
    // The corrections mattered: the file's nominal was 100 × worse.
    assert!(nominal_before > 100.0 * row["mean"].as_f64().unwrap(), "{nominal_before:e} vs {row}");

    // Written again from what it reads, the file is the same text.
    let back = cbd_trainer::data::model_file::load_model_file(dir.join("rr-effects.toml")).unwrap();
    assert_eq!(cbd_trainer::data::model_file::write_model_file(&back, &header(&written)), written);
}

/// The comment lines a written file starts with, without their `# `.
fn header(text: &str) -> String {
    text.lines().take_while(|l| l.starts_with("# ")).map(|l| &l[2..]).collect::<Vec<_>>().join("\n")
}

/// `cbd compensate` with a `[planar]` frame: targets are read into the chain's frame and the
/// commands handed back in the arm's joints (offsets removed) — the same commands as the frame-free
/// file given the hand-moved targets and seeds, less the offsets.
#[test]
fn compensate_takes_targets_in_the_arms_frame_and_gives_the_arms_joints() {
    let dir = scratch("planar-frame-compensate");
    let arm = EffectArm::new(planar_arm(&[1.02, 0.49], [0.0, 0.0], 0.0, &[0.0, 0.0]));
    let train = arm.measure_planar(&configurations(Sampling::Grid { per_axis: 8 }, 2), 0.0, 1);
    write(&dir, "train.csv", csv(&train));
    let frame = cbd_trainer::nominal::planar::PlanarFrame { offsets: vec![0.1, -0.2], base: [0.3, -0.1], yaw: 0.4 };
    let framed =
        PLANAR_RR_MODEL.replace("lengths = [1.0, 0.5]", "lengths = [1.0, 0.5]\nbase = [0.3, -0.1]\nyaw = 0.4\noffsets = [0.1, -0.2]");
    write(&dir, "framed.toml", framed);
    write(&dir, "plain.toml", PLANAR_RR_MODEL);
    succeeds(&fit_without_search(&dir, "framed.toml", "train.csv", "a.blob"));
    let (targets, seeds) = ([[0.9, 0.8], [0.2, 1.1], [-0.7, 0.5]], [[0.5, 0.9], [1.2, 0.8], [2.0, 1.0]]);
    let rows = |head: &str, v: &[[f64; 2]]| head.to_string() + &v.iter().map(|r| format!("{:?},{:?}\n", r[0], r[1])).collect::<String>();
    write(&dir, "t.csv", rows("x,y\n", &targets));
    write(&dir, "s.csv", rows("q1,q2\n", &seeds));
    let moved_targets: Vec<[f64; 2]> = targets.iter().map(|t| frame.to_chain(t)).collect();
    let moved_seeds: Vec<[f64; 2]> = seeds.iter().map(|s| [s[0] + 0.1, s[1] - 0.2]).collect();
    write(&dir, "tc.csv", rows("x,y\n", &moved_targets));
    write(&dir, "sc.csv", rows("q1,q2\n", &moved_seeds));
    // a.blob records its import frame (format 9) and is refused through plain.toml; the same
    // calibration without the record (as a blob written before format 9) is read through it.
    let refused = cbd(&dir, &["compensate", "--model", "plain.toml", "--blob", "a.blob", "--targets", "tc.csv", "--out", "c0.csv"]);
    assert_eq!(refused.status.code(), Some(1), "{}", String::from_utf8_lossy(&refused.stderr));
    let bytes = std::fs::read(dir.join("a.blob")).unwrap();
    let mut unrecorded = cbd_protocol::decode(&bytes).unwrap();
    assert!(unrecorded.provenance.take().is_some_and(|p| p.import_frame.is_some()));
    std::fs::write(dir.join("b.blob"), cbd_protocol::encode_to_vec(&unrecorded).unwrap()).unwrap();
    for (model, blob, t, s, out) in
        [("framed.toml", "a.blob", "t.csv", "s.csv", "c1.csv"), ("plain.toml", "b.blob", "tc.csv", "sc.csv", "c2.csv")]
    {
        succeeds(&cbd(&dir, &["compensate", "--model", model, "--blob", blob, "--targets", t, "--seeds", s, "--out", out]));
    }
    let read = |name: &str| -> Vec<Vec<f64>> {
        let text = std::fs::read_to_string(dir.join(name)).unwrap();
        text.lines().skip(1).map(|l| l.split(',').take(3).map(|v| v.parse().unwrap()).collect()).collect()
    };
    let (framed, plain) = (read("c1.csv"), read("c2.csv"));
    assert_eq!(framed.len(), 3);
    for (a, b) in framed.iter().zip(&plain) {
        assert!((a[0] - (b[0] - 0.1)).abs() < 1e-12 && (a[1] - (b[1] + 0.2)).abs() < 1e-12, "{a:?} vs {b:?}");
        assert_eq!(a[2], b[2], "residual");
    }
}

//! Arbitrary bytes → the measurement CSV reader (UR5-like column spec) and the model-file parser.
//!
//! Both must return data or an `ImportError` naming the file; any panic is a bug. The first byte
//! chooses the angle/length units and which parser(s) run, the rest is the file.
#![no_main]

use cbd_protocol::JointKind;
use cbd_trainer::data::csv_import::{read_measurements_from, ColumnSpec};
use cbd_trainer::data::model_file::{parse_model_file, AngleUnit, ImportError, LengthUnit};
use libfuzzer_sys::fuzz_target;
use std::path::Path;

fn ur5_spec(flags: u8) -> ColumnSpec {
    let joints = ["q1_deg", "q2_deg", "q3_deg", "q4_deg", "q5_deg", "q6_deg"];
    let mut kinds = vec![JointKind::Revolute; 6];
    if flags & 8 != 0 {
        kinds[2] = JointKind::Prismatic;
    }
    ColumnSpec {
        joint_columns: joints.iter().map(|s| s.to_string()).collect(),
        position_columns: ["x_mm", "y_mm", "z_mm"].iter().map(|s| s.to_string()).collect(),
        joint_limits: cbd_trainer::data::csv_import::default_joint_limits(&kinds),
        repeat_tolerance: None,
        joint_map: None,
        planar_frame: None,
        tool_points: Vec::new(),
        orientation_columns: None,
        order: cbd_trainer::data::RowOrder::Measured,
        range_hint: cbd_trainer::data::csv_import::RANGE_FROM_MODEL_FILE,
        joint_kinds: kinds,
        angle_unit: if flags & 2 != 0 { AngleUnit::Rad } else { AngleUnit::Deg },
        length_unit: if flags & 4 != 0 { LengthUnit::M } else { LengthUnit::Mm },
        model_length_unit: LengthUnit::Mm,
        min_rows: (flags >> 4) as usize,
    }
}

fn names_the_file(e: &ImportError, file: &str) {
    let text = e.to_string();
    assert!(text.contains(file), "error does not name the file: {text}");
}

fuzz_target!(|input: &[u8]| {
    let Some((&flags, body)) = input.split_first() else { return };
    if flags & 1 == 0 {
        let path = Path::new("fuzz/measurements.csv");
        match read_measurements_from(body, path, &ur5_spec(flags)) {
            Ok(imported) => {
                let m = &imported.measurements;
                assert_eq!(m.joints.len(), m.len() * 6);
                assert_eq!(m.positions.len(), m.len() * 3);
                assert_eq!(imported.lines.len(), m.len());
                assert!(m.joints.iter().chain(&m.positions).all(|v| v.is_finite()), "non-finite value imported");
            }
            Err(e) => names_the_file(&e, "fuzz/measurements.csv"),
        }
    } else if let Ok(text) = std::str::from_utf8(body) {
        // A [urdf] section names a file relative to the model file: anchor it in a directory
        // that does not exist so that the fuzzer never reads the file system.
        let path = Path::new("/nonexistent-cbd-fuzz/model.toml");
        if text.contains("..") || text.contains("\"/") || text.contains("'/") {
            return;
        }
        match parse_model_file(text, path) {
            Ok(model) => {
                // Whatever parses must give a consistent column spec or a clear error.
                let _ = model.column_spec();
            }
            Err(e) => names_the_file(&e, "/nonexistent-cbd-fuzz/model.toml"),
        }
    }
});

//! Arbitrary bytes → the URDF reader and its conversion to a DH chain, and the model-file parser.
//!
//! The first byte chooses the length scale and which input runs; the rest is the file. A URDF
//! that parses is converted between its first and last link (and between two links chosen by the
//! flag byte); the conversion must return a chain whose values are all finite, or an error. Any
//! panic, hang (libFuzzer's -timeout) or blow-up (-rss_limit_mb) is a bug.
#![no_main]

use cbd_protocol::NominalModel;
use cbd_trainer::data::model_file::parse_model_file;
use cbd_trainer::nominal::urdf::chain_from_urdf;
use libfuzzer_sys::fuzz_target;
use std::path::Path;

/// Inputs above this size are skipped: the reader itself caps URDF files (8 MiB), and larger
/// inputs only slow the fuzzer down.
const MAX_INPUT: usize = 1 << 16;

fn check_urdf(text: &str, flags: u8) {
    let Ok(robot) = cbd_trainer::nominal::urdf::parse(text) else { return };
    let names: Vec<&str> = robot.links.iter().map(|l| l.name.as_str()).collect();
    let (Some(first), Some(last)) = (names.first(), names.last()) else { return };
    let scale = if flags & 2 != 0 { 1000.0 } else { 1.0 };
    let picked = (names[flags as usize % names.len()], names[(flags as usize / 7) % names.len()]);
    for (base, tip) in [(*first, *last), picked] {
        if let Ok(conv) = chain_from_urdf(&robot, base, tip, scale) {
            assert_eq!(conv.joint_names.len(), conv.chain.joints.len());
            let model = NominalModel::DhChain(conv.chain);
            let q = vec![0.3; model.n_joints()];
            let k = cbd_runtime::internals::kinematics::forward_kinematics(&model, &q);
            assert!(k.position.iter().all(|v| !v.is_nan()), "NaN position from a converted URDF");
        }
    }
}

fuzz_target!(|input: &[u8]| {
    let Some((&flags, body)) = input.split_first() else { return };
    if body.len() > MAX_INPUT {
        return;
    }
    let Ok(text) = std::str::from_utf8(body) else { return };
    if flags & 1 == 0 {
        check_urdf(text, flags);
    } else {
        // The model file with no URDF section reachable on disk: a [urdf] path is anchored in a
        // directory that does not exist, and paths escaping it are skipped.
        if text.contains("..") || text.contains("\"/") || text.contains("'/") {
            return;
        }
        if let Err(e) = parse_model_file(text, Path::new("/nonexistent-cbd-fuzz/model.toml")) {
            assert!(e.to_string().contains("/nonexistent-cbd-fuzz/model.toml"), "error does not name the file: {e}");
        }
    }
});

//! The blobs' bytes, pinned: the demo blob (`cbd demo`), the UR5 example blob (`cbd fit` on
//! `examples/ur5`) and the firmware check's blobs (`cbd-fw-host make-blobs`) must keep their exact
//! SHA-256, so a restructuring that claims "behaviour unchanged" is checked byte for byte.
//!
//! Re-derive a figure with the project's own tools and `sha256sum`, e.g.
//! `cbd demo --quiet --out rr.blob` or `cargo run -p cbd-fw-host -- make-blobs DIR`. SHA-256 from the
//! `sha2` crate (RustCrypto).
//! The firmware blobs are built with integer and exactly rounded arithmetic only (the same bytes on
//! every machine); the trained blobs also depend on the floating-point kernels faer picks for the
//! CPU, so a different SIMD level may legitimately change them: re-pin there, never here.

use std::path::{Path, PathBuf};
use std::process::Command;

// The firmware check's blob builders, compiled here exactly as `cbd-fw-host` compiles them.
#[path = "../../examples/fw-host/src/blobs.rs"]
#[allow(dead_code)]
mod blobs;
#[path = "../../examples/firmware/src/shared.rs"]
#[allow(dead_code)]
mod shared;

const CBD: &str = env!("CARGO_BIN_EXE_cbd");

/// SHA-256, lower-case hex, as `sha256sum` prints it.
fn sha256_hex(bytes: &[u8]) -> String {
    use sha2::{Digest, Sha256};
    Sha256::digest(bytes).iter().map(|b| format!("{b:02x}")).collect()
}

/// The trained blobs' pins were recorded on x86-64 with AVX2 and FMA (faer's kernels for that level);
/// elsewhere the floating-point kernels may differ, and the check says so instead of failing.
fn same_float_kernels_as_the_pins() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        if std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma") {
            return true;
        }
    }
    eprintln!("skipped: the trained blobs were pinned on x86-64 with AVX2 + FMA; this CPU's floating-point kernels differ");
    false
}

fn scratch(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("cbd-blob-hashes-{name}"));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Runs `cbd ARGS --out DIR/out.blob` and returns the blob it wrote.
fn cbd_blob(name: &str, args: &[&str]) -> Vec<u8> {
    let out = scratch(name).join("out.blob");
    let status = Command::new(CBD).args(args).arg("--out").arg(&out).output().expect("run cbd");
    assert!(status.status.success(), "cbd {args:?} failed: {}", String::from_utf8_lossy(&status.stderr));
    std::fs::read(&out).unwrap()
}

#[test]
fn demo_blob_is_unchanged() {
    if !same_float_kernels_as_the_pins() {
        return;
    }
    // The blob is written before the test configurations are evaluated: their count does not enter it.
    let blob = cbd_blob("demo", &["demo", "--quiet", "--test-points", "1"]);
    assert_eq!((blob.len(), sha256_hex(&blob).as_str()), (8334, "8672f4262492ad09f55712277d16d36e8c3820f4109ff7154b5344efe0bb9b08"));
}

#[test]
fn ur5_example_blob_is_unchanged() {
    if !same_float_kernels_as_the_pins() {
        return;
    }
    let ur5 = concat!(env!("CARGO_MANIFEST_DIR"), "/../examples/ur5");
    let (model, data) = (format!("{ur5}/ur5.toml"), format!("{ur5}/train.csv"));
    let blob = cbd_blob("ur5", &["fit", "--quiet", "--model", &model, "--data", &data]);
    assert_eq!((blob.len(), sha256_hex(&blob).as_str()), (72555, "879b3d13b2d7939b65485ab5dcd384f1b9a5cd1e159422046ddc2fc5450b4153"));
}

#[test]
fn firmware_blobs_are_unchanged() {
    use blobs::*;
    let pins = [
        ("rr", rr_reference_blob(), 8334, "b270e30005e24193844ca2f85f1a101941b6d63cbf9b50ca390e8dd2b4709eb9"),
        ("six", six_joint_blob(), 5160, "63ccae97ebe5fd9b327ac95aea5bed01a7949acd39f4824f9f2f7761a2d27e14"),
        ("six-effects", six_effects_blob(), 5335, "fa3f5634e8bfeedc64e5309282994e4531bc14a0c397e804f50d268e0b546af5"),
        ("rr64", rr_grid_blob(8, 0x0000_0064, DEMO_SCHEME), 2189, "d8f5ff2054e2f5dd6862b05b52dec1b631a919c4d0ee6254f84e4b966ba1483b"),
        ("rr256", rr_grid_blob(16, 0x0000_0100, DEMO_SCHEME), 8334, "e66481bb34d8bbebd97169ddb459039e8cb5fc7a8c1adf2aa4ec0f4561b3d044"),
        ("rr1024", rr_grid_blob(32, 0x0000_0400, DEMO_SCHEME), 32912, "a5e7fef82e51146408ada6c79dfe043bd8343d44457b8d6189c5fdbc9d59d81f"),
    ];
    for (name, blob, len, sha) in pins {
        assert_eq!((blob.len(), sha256_hex(&blob).as_str()), (len, sha), "firmware blob {name}");
    }
}

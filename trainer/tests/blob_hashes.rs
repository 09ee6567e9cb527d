//! The blobs' bytes, pinned: the demo blob (`cbd demo`), the UR5 example blob (`cbd fit` on
//! `examples/ur5`) and the firmware check's blobs (`cbd-fw-host make-blobs`) must keep their exact
//! SHA-256, so a restructuring that claims "behaviour unchanged" is checked byte for byte.
//!
//! Re-derive a figure with the project's own tools and `sha256sum`, e.g.
//! `cbd demo --quiet --out rr.blob` or `cargo run -p cbd-fw-host -- make-blobs DIR`.
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

/// SHA-256 (FIPS 180-4), written out so the pins can be compared with `sha256sum`.
fn sha256_hex(bytes: &[u8]) -> String {
    const K: [u32; 64] = [
        0x428a2f98, 0x71374491, 0xb5c0fbcf, 0xe9b5dba5, 0x3956c25b, 0x59f111f1, 0x923f82a4, 0xab1c5ed5, 0xd807aa98, 0x12835b01, 0x243185be,
        0x550c7dc3, 0x72be5d74, 0x80deb1fe, 0x9bdc06a7, 0xc19bf174, 0xe49b69c1, 0xefbe4786, 0x0fc19dc6, 0x240ca1cc, 0x2de92c6f, 0x4a7484aa,
        0x5cb0a9dc, 0x76f988da, 0x983e5152, 0xa831c66d, 0xb00327c8, 0xbf597fc7, 0xc6e00bf3, 0xd5a79147, 0x06ca6351, 0x14292967, 0x27b70a85,
        0x2e1b2138, 0x4d2c6dfc, 0x53380d13, 0x650a7354, 0x766a0abb, 0x81c2c92e, 0x92722c85, 0xa2bfe8a1, 0xa81a664b, 0xc24b8b70, 0xc76c51a3,
        0xd192e819, 0xd6990624, 0xf40e3585, 0x106aa070, 0x19a4c116, 0x1e376c08, 0x2748774c, 0x34b0bcb5, 0x391c0cb3, 0x4ed8aa4a, 0x5b9cca4f,
        0x682e6ff3, 0x748f82ee, 0x78a5636f, 0x84c87814, 0x8cc70208, 0x90befffa, 0xa4506ceb, 0xbef9a3f7, 0xc67178f2,
    ];
    let mut h: [u32; 8] = [0x6a09e667, 0xbb67ae85, 0x3c6ef372, 0xa54ff53a, 0x510e527f, 0x9b05688c, 0x1f83d9ab, 0x5be0cd19];
    let mut message = bytes.to_vec();
    message.push(0x80);
    while message.len() % 64 != 56 {
        message.push(0);
    }
    message.extend_from_slice(&((bytes.len() as u64) * 8).to_be_bytes());
    for block in message.chunks_exact(64) {
        let mut w = [0u32; 64];
        for (t, word) in block.chunks_exact(4).enumerate() {
            w[t] = u32::from_be_bytes([word[0], word[1], word[2], word[3]]);
        }
        for t in 16..64 {
            let s0 = w[t - 15].rotate_right(7) ^ w[t - 15].rotate_right(18) ^ (w[t - 15] >> 3);
            let s1 = w[t - 2].rotate_right(17) ^ w[t - 2].rotate_right(19) ^ (w[t - 2] >> 10);
            w[t] = w[t - 16].wrapping_add(s0).wrapping_add(w[t - 7]).wrapping_add(s1);
        }
        let [mut a, mut b, mut c, mut d, mut e, mut f, mut g, mut hh] = h;
        for t in 0..64 {
            let s1 = e.rotate_right(6) ^ e.rotate_right(11) ^ e.rotate_right(25);
            let ch = (e & f) ^ (!e & g);
            let t1 = hh.wrapping_add(s1).wrapping_add(ch).wrapping_add(K[t]).wrapping_add(w[t]);
            let s0 = a.rotate_right(2) ^ a.rotate_right(13) ^ a.rotate_right(22);
            let maj = (a & b) ^ (a & c) ^ (b & c);
            let t2 = s0.wrapping_add(maj);
            (hh, g, f, e, d, c, b, a) = (g, f, e, d.wrapping_add(t1), c, b, a, t1.wrapping_add(t2));
        }
        for (x, y) in h.iter_mut().zip([a, b, c, d, e, f, g, hh]) {
            *x = x.wrapping_add(y);
        }
    }
    h.iter().map(|x| format!("{x:08x}")).collect()
}

#[test]
fn sha256_matches_the_standard_test_vectors() {
    assert_eq!(sha256_hex(b""), "e3b0c44298fc1c149afbf4c8996fb92427ae41e4649b934ca495991b7852b855");
    assert_eq!(sha256_hex(b"abc"), "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad");
    assert_eq!(
        sha256_hex(b"abcdbcdecdefdefgefghfghighijhijkijkljklmklmnlmnomnopnopq"),
        "248d6a61d20638b8e5c026930c3e6039a33ce45964ff2167f6ecedd419db06c1"
    );
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
    // The blob is written before the test configurations are evaluated: their count does not enter it.
    let blob = cbd_blob("demo", &["demo", "--quiet", "--test-points", "1"]);
    assert_eq!((blob.len(), sha256_hex(&blob).as_str()), (8334, "8672f4262492ad09f55712277d16d36e8c3820f4109ff7154b5344efe0bb9b08"));
}

#[test]
fn ur5_example_blob_is_unchanged() {
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

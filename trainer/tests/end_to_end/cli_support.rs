//! Running the built `cbd` binary in a scratch directory, for the CLI-level test files.
#![allow(dead_code)] // each test file uses its own part

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

pub const CBD: &str = env!("CARGO_BIN_EXE_cbd");

pub fn ur5_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../examples/ur5")
}

/// A fresh scratch directory per test.
pub fn scratch(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("cbd-cli-{name}"));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

pub fn cbd(dir: &Path, args: &[&str]) -> Output {
    Command::new(CBD).args(args).current_dir(dir).output().expect("run cbd")
}

/// `cbd` under an address-space limit of `kib` KiB (`ulimit -v`).
pub fn cbd_limited(dir: &Path, kib: u64, args: &[&str]) -> Output {
    let quoted: Vec<String> = args.iter().map(|a| format!("'{}'", a.replace('\'', "'\\''"))).collect();
    Command::new("sh")
        .args(["-c", &format!("ulimit -v {kib} && exec {CBD} {}", quoted.join(" "))])
        .current_dir(dir)
        .output()
        .expect("run cbd under ulimit")
}

pub fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// Exit code 1, no panic, an `error:` line, and every needle in stderr.
#[track_caller]
pub fn fails_with(out: &Output, needles: &[&str]) -> String {
    let err = stderr(out);
    assert!(!err.contains("panicked"), "panic:\n{err}");
    assert_eq!(out.status.code(), Some(1), "exit code; stderr:\n{err}");
    assert!(err.lines().any(|l| l.starts_with("error: ")), "no `error:` line:\n{err}");
    for n in needles {
        assert!(err.contains(n), "stderr lacks {n:?}:\n{err}");
    }
    err
}

/// Exit code 0; returns stderr.
#[track_caller]
pub fn succeeds(out: &Output) -> String {
    let err = stderr(out);
    assert!(out.status.success(), "exit {:?}; stderr:\n{err}", out.status.code());
    err
}

pub fn write(dir: &Path, name: &str, bytes: impl AsRef<[u8]>) -> String {
    std::fs::write(dir.join(name), bytes).unwrap();
    name.to_string()
}

/// The first `rows` data rows of the UR5 example's training file (header kept).
pub fn ur5_head(dir: &Path, name: &str, rows: usize) -> String {
    let text = std::fs::read_to_string(ur5_dir().join("train.csv")).unwrap();
    let head: Vec<&str> = text.lines().take(rows + 1).collect();
    write(dir, name, head.join("\n") + "\n")
}

pub fn ur5_model() -> String {
    ur5_dir().join("ur5.toml").to_str().unwrap().to_string()
}

/// A planar two-link model file (l = 1, 0.5 m; columns q1, q2, x, y).
pub const PLANAR_RR_MODEL: &str = "length_unit = \"m\"\nangle_unit = \"rad\"\n[planar]\nlengths = [1.0, 0.5]\n[measurements]\njoints = [\"q1\", \"q2\"]\npositions = [\"x\", \"y\"]\n";

/// `cbd simulate --grid k` into `name`.
pub fn rr_grid(dir: &Path, name: &str, per_axis: usize) -> String {
    succeeds(&cbd(dir, &["simulate", "--grid", &per_axis.to_string(), "--out", name]));
    name.to_string()
}

/// The first `rows` data rows of CSV file `from` (in `dir`) as `name`.
pub fn head(dir: &Path, from: &str, name: &str, rows: usize) -> String {
    let text = std::fs::read_to_string(dir.join(from)).unwrap();
    let head: Vec<&str> = text.lines().take(rows + 1).collect();
    write(dir, name, head.join("\n") + "\n")
}

/// A copy of the blob at `from` whose last momentum is `value`: checksum and fields valid, the
/// model damaged (positions of about `value` times the arm's size).
pub fn damaged_blob(dir: &std::path::Path, from: &str, to: &str, value: f64) -> String {
    let blob = std::fs::read(dir.join(from)).unwrap();
    let mut model = cbd_protocol::decode(&blob).unwrap();
    let mut momenta: Vec<f64> = model.momenta.iter().collect();
    *momenta.last_mut().unwrap() = value;
    let bytes = cbd_protocol::f64_le_bytes(&momenta);
    model.momenta = cbd_protocol::F64Slice::from_le_bytes(&bytes);
    write(dir, to, cbd_protocol::encode_to_vec(&model).unwrap())
}

/// `cbd fit` with every hyperparameter and the geometry given, so no search runs (a few seconds to
/// minutes saved where any blob of the model serves): `cbd fit --model MODEL --data DATA --out OUT`
/// plus these.
pub fn fit_without_search(dir: &Path, model: &str, data: &str, out: &str) -> Output {
    let fixed = ["--sigma", "0.05", "--task-width", "500", "--task-gamma", "1", "--joint-b", "1", "--gamma", "1e-4"];
    let scheme = ["--steps", "1", "--integrator", "euler", "--geometry", "nominal", "--quiet"];
    cbd(dir, &[&["fit", "--model", model, "--data", data, "--out", out][..], &fixed[..], &scheme[..]].concat())
}

/// The repository's examples/ directory.
pub fn examples() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../examples")
}

/// Runs `cbd` in `dir`, which must succeed; returns its stdout.
#[track_caller]
pub fn run(dir: &Path, args: &[&str]) -> String {
    let out = cbd(dir, args);
    assert!(out.status.success(), "cbd {args:?}: {}", stderr(&out));
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// A JSON file the CLI wrote.
pub fn json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

/// CRC-32 (ISO-HDLC, zlib's), the blob's trailer.
pub fn crc32(bytes: &[u8]) -> u32 {
    let mut crc = 0xFFFF_FFFFu32;
    for &b in bytes {
        crc ^= u32::from(b);
        for _ in 0..8 {
            crc = if crc & 1 == 1 { (crc >> 1) ^ 0xEDB8_8320 } else { crc >> 1 };
        }
    }
    !crc
}

/// A blob whose payload `edit` changed, framed again (payload length and checksum valid): a crafted
/// blob whose frame passes every check and whose model is whatever the edit made it.
pub fn reframe(blob: &[u8], edit: impl FnOnce(&mut Vec<u8>)) -> Vec<u8> {
    const HEADER: usize = 10;
    let mut payload = blob[HEADER..blob.len() - 4].to_vec();
    edit(&mut payload);
    let mut out = blob[..6].to_vec();
    out.extend_from_slice(&(payload.len() as u32).to_le_bytes());
    out.extend_from_slice(&payload);
    let crc = crc32(&out);
    out.extend_from_slice(&crc.to_le_bytes());
    out
}

/// Replaces the `nth` (0-based) occurrence of `from`'s little-endian bytes in `bytes` by `to`'s.
pub fn replace_f64(bytes: &mut [u8], from: f64, to: f64, nth: usize) {
    let pattern = from.to_le_bytes();
    let at = bytes.windows(8).enumerate().filter(|(_, w)| *w == pattern).map(|(i, _)| i).nth(nth).expect("value in the payload");
    bytes[at..at + 8].copy_from_slice(&to.to_le_bytes());
}

/// `cbd args` in `dir`, killed after `seconds`: a hang fails the test (panics) instead of
/// blocking the suite. Output as [`cbd`]'s.
#[track_caller]
pub fn cbd_within(dir: &Path, seconds: u64, args: &[&str]) -> Output {
    use std::process::Stdio;
    let mut child = Command::new(CBD).args(args).current_dir(dir).stdout(Stdio::piped()).stderr(Stdio::piped()).spawn().expect("run cbd");
    // Drain both pipes while waiting: a chatty run must not block on a full pipe.
    let (mut out, mut err) = (child.stdout.take().unwrap(), child.stderr.take().unwrap());
    let stdout = std::thread::spawn(move || {
        let mut v = Vec::new();
        std::io::Read::read_to_end(&mut out, &mut v).ok();
        v
    });
    let stderr = std::thread::spawn(move || {
        let mut v = Vec::new();
        std::io::Read::read_to_end(&mut err, &mut v).ok();
        v
    });
    let start = std::time::Instant::now();
    let status = loop {
        if let Some(status) = child.try_wait().unwrap() {
            break status;
        }
        if start.elapsed().as_secs() >= seconds {
            let _ = child.kill();
            let _ = child.wait();
            panic!("cbd {args:?} did not finish within {seconds} s");
        }
        std::thread::sleep(std::time::Duration::from_millis(5));
    };
    Output { status, stdout: stdout.join().unwrap(), stderr: stderr.join().unwrap() }
}

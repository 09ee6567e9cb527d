//! Arbitrary bytes → `Calibrator::load` into fixed storage → evaluate a few configurations, and
//! compensate (the nominal inverse kinematics, then `Calibrator::compensate`) towards targets made
//! of the same values (NaN, ∞, huge, wrong lengths included).
//!
//! Every input is tried twice: as a raw blob (exercises the frame checks: magic, version,
//! length, CRC), and with its header and checksum repaired around bytes 10..len-4 (so that
//! mutations reach the postcard payload decoder, `Model::validate`, the control-point
//! integration and `evaluate`, which a CRC would otherwise shield from almost every mutation).
//! Loading and evaluation must return a value or a typed error; any panic is a bug.
#![no_main]

use cbd_protocol::{DecodeError, FORMAT_VERSION, HEADER_LEN, MAGIC, OLDEST_FORMAT_VERSION, TRAILER_LEN};
use cbd_runtime::{Calibrator, Error};
use libfuzzer_sys::fuzz_target;

/// Fixed storage, as on a controller: larger models must fail with `StorageTooSmall`.
const STORAGE: usize = 1 << 16;

fn reframe(data: &[u8]) -> Option<Vec<u8>> {
    let payload = data.get(HEADER_LEN..data.len().checked_sub(TRAILER_LEN)?)?;
    let mut blob = Vec::with_capacity(data.len());
    blob.extend_from_slice(&MAGIC);
    // The input's own version when this build reads it (format 5 adds a tail to the payload).
    let version = u16::from_le_bytes([*data.get(4)?, *data.get(5)?]).clamp(OLDEST_FORMAT_VERSION, FORMAT_VERSION);
    blob.extend_from_slice(&version.to_le_bytes());
    blob.extend_from_slice(&(payload.len() as u32).to_le_bytes());
    blob.extend_from_slice(payload);
    let crc = crc32(&blob);
    blob.extend_from_slice(&crc.to_le_bytes());
    Some(blob)
}

/// CRC-32/ISO-HDLC, bitwise (no dependency on the protocol's private checksum).
fn crc32(bytes: &[u8]) -> u32 {
    let mut crc = !0u32;
    for &b in bytes {
        crc ^= b as u32;
        for _ in 0..8 {
            crc = if crc & 1 != 0 { (crc >> 1) ^ 0xEDB8_8320 } else { crc >> 1 };
        }
    }
    !crc
}

/// Configurations derived from the input: a few in [-2π, 2π), plus one with raw f64 bits
/// (NaN, ∞, huge, subnormal), plus wrong lengths.
fn queries(data: &[u8], n: usize) -> Vec<Vec<f64>> {
    let byte = |i: usize| data.get(i % data.len().max(1)).copied().unwrap_or(0) as f64;
    let mut out = Vec::new();
    for k in 0..3 {
        out.push((0..n).map(|d| (byte(7 * k + 3 * d + 1) - 128.0) / 128.0 * 2.0 * std::f64::consts::PI).collect());
    }
    let raw: Vec<f64> = (0..n)
        .map(|d| {
            let mut b = [0u8; 8];
            for (j, x) in b.iter_mut().enumerate() {
                *x = byte(data.len().wrapping_sub(1 + 8 * d + j)) as u8;
            }
            f64::from_le_bytes(b)
        })
        .collect();
    out.push(raw);
    out.push(vec![0.0; n + 1]);
    out.push(Vec::new());
    out
}

fn load_and_evaluate(blob: &[u8], data: &[u8], storage: &mut [f64]) {
    let mut cal = match Calibrator::load(blob, storage) {
        Ok(cal) => cal,
        Err(Error::Blob(_)) | Err(Error::StorageTooSmall { .. }) | Err(Error::Diverged) => return,
        Err(e) => panic!("unexpected load error {e:?}"),
    };
    let n = cal.model().n_joints();
    let m = cal.model().task_dim();
    for q in queries(data, n) {
        match cal.evaluate(&q) {
            Ok(e) => {
                assert!(q.len() == n && q.iter().all(|v| v.is_finite()));
                assert_eq!(e.position().len(), m);
                assert!(e.position().iter().all(|v| v.is_finite()), "non-finite position returned as Ok");
                assert!(e.jacobian().iter().all(|v| v.is_finite()), "non-finite Jacobian returned as Ok");
            }
            Err(Error::QueryDimension { .. }) => assert!(q.len() != n),
            Err(Error::NonFiniteQuery { .. }) => assert!(q.iter().any(|v| !v.is_finite())),
            Err(Error::NonFiniteResult) => {}
            Err(e) => panic!("unexpected evaluate error {e:?}"),
        }
    }
    // Compensation: every query as a seed, every query's first m values as a target.
    let nominal = cal.model().nominal.clone();
    let scale = cal.model().normalisation.task_scale;
    let all = queries(data, n);
    for (seed, target_source) in all.iter().zip(all.iter().rev()) {
        let target: Vec<f64> = target_source.iter().copied().take(m).collect();
        let mut start = vec![0.0; seed.len()];
        let seed = match cbd_runtime::internals::inverse_kinematics::nominal_position(&nominal, &target, seed, &mut start, 4, scale) {
            Some(_) => start,
            None => seed.clone(),
        };
        let mut out = vec![0.0; n];
        match cal.compensate(&target, &seed, &mut out) {
            Ok(c) => {
                assert!(target.len() == m && seed.len() == n);
                assert!(out.iter().all(|v| v.is_finite()), "non-finite command returned as Ok");
                assert!(!c.residual.is_nan() && c.residual >= 0.0);
                assert!(!c.reached || c.residual.is_finite());
            }
            Err(Error::TargetDimension { .. }) => assert!(target.len() != m),
            Err(Error::QueryDimension { .. }) => assert!(seed.len() != n),
            Err(Error::NonFiniteTarget { .. }) => assert!(target.iter().any(|v| !v.is_finite())),
            Err(Error::NonFiniteQuery { .. }) => assert!(seed.iter().any(|v| !v.is_finite())),
            Err(Error::NonFiniteResult) => {}
            Err(e) => panic!("unexpected compensate error {e:?}"),
        }
    }
}

fuzz_target!(|data: &[u8]| {
    thread_local! {
        static STORE: std::cell::RefCell<Vec<f64>> = std::cell::RefCell::new(vec![0.0; STORAGE]);
    }
    STORE.with(|s| {
        let mut s = s.borrow_mut();
        // Raw: the frame checks decide.
        let raw = cbd_protocol::decode(data).err();
        if data.len() >= 4 && data[..4] != MAGIC && data.len() >= HEADER_LEN + TRAILER_LEN {
            assert_eq!(raw, Some(DecodeError::BadMagic));
        }
        load_and_evaluate(data, data, &mut s);
        // Re-framed: the payload decides.
        if let Some(blob) = reframe(data) {
            load_and_evaluate(&blob, data, &mut s);
        }
    });
});

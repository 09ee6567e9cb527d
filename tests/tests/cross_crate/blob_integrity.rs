//! A blob that cannot lie: every single-bit flip and every truncation of a real blob is rejected
//! by `Calibrator::load` with the error that names what is wrong — never a panic, never a model
//! that loads.
//!
//! Frame: magic "CBDM" (4) | version u16 (2) | payload length u32 (4) | payload | CRC-32 (4).
//! The expected error of a flip depends only on where it lands:
//! magic → `BadMagic`, version → `UnsupportedVersion` (or `ChecksumMismatch` when the flip lands on
//! another version this build reads: format 4's bit 0 gives format 5), length → `Truncated` (declared longer) or
//! `TrailingBytes` (declared shorter), payload or CRC → `ChecksumMismatch` (CRC-32 detects every
//! single-bit error).

use cbd_protocol::*;
use cbd_runtime::{Calibrator, Error};
use cbd_trainer::simulate::{configurations, rr, Sampling};
use cbd_trainer::solver::{fit_cbd, CbdOptions};

/// A blob written by the solver: the RR arm on a 6 × 6 grid, 3 LM iterations (N = 36, ~1.3 kB).
fn solver_blob() -> Vec<u8> {
    let data = rr::RealRr::default().measure(&configurations(Sampling::Grid { per_axis: 6 }, 2));
    let mut opts = CbdOptions::paper_rr();
    opts.solver.max_iterations = 3;
    opts.solver.verbose = false;
    fit_cbd(&rr::nominal(), &data, &opts).expect("fit").blob
}

use cbd_tests::reference_blob;

fn storage_for(blob: &[u8]) -> Vec<f64> {
    let m = decode(blob).expect("the intact blob decodes");
    vec![0.0; cbd_runtime::storage_len(m.n_points as usize, m.n_joints(), m.task_dim(), m.integrator)]
}

/// CRC-32/ISO-HDLC, written out here (table-driven) so the test does not trust the code under test.
fn crc32(bytes: &[u8]) -> u32 {
    static TABLE: std::sync::OnceLock<[u32; 256]> = std::sync::OnceLock::new();
    let table = TABLE.get_or_init(|| {
        let mut t = [0u32; 256];
        for (i, v) in t.iter_mut().enumerate() {
            let mut c = i as u32;
            for _ in 0..8 {
                c = if c & 1 != 0 { (c >> 1) ^ 0xEDB8_8320 } else { c >> 1 };
            }
            *v = c;
        }
        t
    });
    let mut crc = !0u32;
    for &b in bytes {
        crc = table[((crc ^ b as u32) & 0xff) as usize] ^ (crc >> 8);
    }
    !crc
}

/// crc32 of `n` zero bytes (memoised: the flip loops ask for the same length many times).
fn zero_crc(n: usize) -> u32 {
    thread_local!(static MEMO: std::cell::RefCell<std::collections::HashMap<usize, u32>> = Default::default());
    MEMO.with(|m| *m.borrow_mut().entry(n).or_insert_with(|| crc32(&vec![0u8; n])))
}

/// What a flip of bit `bit` of byte `byte` must be rejected with.
fn expected_for_flip(blob: &[u8], byte: usize, bit: u32) -> DecodeError {
    let total = blob.len();
    let payload_len = total - HEADER_LEN - TRAILER_LEN;
    let stored = u32::from_le_bytes(blob[total - 4..].try_into().unwrap());
    match byte {
        0..=3 => DecodeError::BadMagic,
        4..=5 => {
            let mut v = [blob[4], blob[5]];
            v[byte - 4] ^= 1 << bit;
            let found = u16::from_le_bytes(v);
            if (cbd_protocol::OLDEST_FORMAT_VERSION..=FORMAT_VERSION).contains(&found) {
                // Another version this build reads: the checksum catches the flip.
                let mut flipped = blob.to_vec();
                flipped[byte] ^= 1 << bit;
                DecodeError::ChecksumMismatch { stored, computed: crc32(&flipped[..total - TRAILER_LEN]) }
            } else {
                DecodeError::UnsupportedVersion { found, supported: FORMAT_VERSION }
            }
        }
        6..=9 => {
            let declared = payload_len ^ (1usize << (bit as usize + 8 * (byte - 6)));
            let declared_total = HEADER_LEN + declared + TRAILER_LEN;
            if declared > payload_len {
                DecodeError::Truncated { needed: declared_total, got: total }
            } else {
                DecodeError::TrailingBytes { expected: declared_total, got: total }
            }
        }
        b if b < total - TRAILER_LEN => {
            // CRC-32 is affine over GF(2): crc(m ⊕ e) = crc(m) ⊕ crc(e) ⊕ crc(0ⁿ) for equal lengths.
            let n = total - TRAILER_LEN;
            let mut e = vec![0u8; n];
            e[b] = 1 << bit;
            let zeros = zero_crc(n);
            DecodeError::ChecksumMismatch { stored, computed: stored ^ crc32(&e) ^ zeros }
        }
        b => {
            let mut t = stored.to_le_bytes();
            t[b - (total - TRAILER_LEN)] ^= 1 << bit;
            DecodeError::ChecksumMismatch { stored: u32::from_le_bytes(t), computed: stored }
        }
    }
}

fn check_rejected(damaged: &[u8], storage: &mut [f64], expected: DecodeError, what: &str) {
    // `decode` and `Calibrator::load` must agree, and neither may panic.
    let decoded = std::panic::catch_unwind(|| decode(damaged).err()).unwrap_or_else(|_| panic!("{what}: decode panicked"));
    assert_eq!(decoded, Some(expected), "{what}: decode");
    match Calibrator::load(damaged, storage) {
        Err(Error::Blob(e)) => assert_eq!(e, expected, "{what}: load"),
        Err(e) => panic!("{what}: load failed with {e:?}, expected Blob({expected:?})"),
        Ok(_) => panic!("{what}: a damaged blob loaded"),
    }
}

/// Flips every bit of every byte of the frame, and of every `stride`-th payload byte (1: all).
fn every_bit_flip_is_rejected(blob: &[u8], stride: usize) {
    let mut storage = storage_for(blob);
    assert!(Calibrator::load(blob, &mut storage).is_ok(), "the intact blob loads");
    assert_eq!(crc32(&blob[..blob.len() - 4]).to_le_bytes(), blob[blob.len() - 4..], "this test's CRC-32 matches the format's");
    let mut damaged = blob.to_vec();
    let mut counts = std::collections::BTreeMap::<&str, usize>::new();
    let payload = HEADER_LEN..blob.len() - TRAILER_LEN;
    let bytes = (0..blob.len()).filter(|b| !payload.contains(b) || (b - HEADER_LEN) % stride == 0);
    let flipped_bytes = bytes.clone().count();
    for byte in bytes {
        for bit in 0..8 {
            damaged[byte] ^= 1 << bit;
            let expected = expected_for_flip(blob, byte, bit);
            check_rejected(&damaged, &mut storage, expected, &format!("bit {bit} of byte {byte} flipped"));
            *counts
                .entry(match expected {
                    DecodeError::BadMagic => "BadMagic",
                    DecodeError::UnsupportedVersion { .. } => "UnsupportedVersion",
                    DecodeError::Truncated { .. } => "Truncated",
                    DecodeError::TrailingBytes { .. } => "TrailingBytes",
                    DecodeError::ChecksumMismatch { .. } => "ChecksumMismatch",
                    _ => unreachable!(),
                })
                .or_default() += 1;
            damaged[byte] ^= 1 << bit;
        }
    }
    assert_eq!(damaged, blob);
    // Every class of field was exercised.
    assert_eq!(counts["BadMagic"], 32);
    // 16 version bits: a flip that lands on a format this build reads (format 4's bit 0 gives 5, its
    // bit 1 gives 6) is caught by the checksum (the CRC covers the header); the others are refused as versions.
    let own = u16::from_le_bytes([blob[4], blob[5]]);
    let readable = (0..16).filter(|b| (cbd_protocol::OLDEST_FORMAT_VERSION..=FORMAT_VERSION).contains(&(own ^ (1 << b)))).count();
    assert_eq!((own, readable), (FORMAT_WITHOUT_EXPANSION, 2));
    assert_eq!(counts["UnsupportedVersion"], 16 - readable);
    assert_eq!(counts["Truncated"] + counts["TrailingBytes"], 32);
    assert!(counts["Truncated"] > 0 && counts["TrailingBytes"] > 0, "{counts:?}");
    assert_eq!(counts["ChecksumMismatch"], 8 * (flipped_bytes - HEADER_LEN) + readable);
    if stride == 1 {
        assert_eq!(flipped_bytes, blob.len());
    }
}

fn every_truncation_and_extension_is_rejected(blob: &[u8]) {
    let mut storage = storage_for(blob);
    let total = blob.len();
    for len in 0..total {
        let needed = if len < HEADER_LEN + TRAILER_LEN { HEADER_LEN + TRAILER_LEN } else { total };
        check_rejected(&blob[..len], &mut storage, DecodeError::Truncated { needed, got: len }, &format!("truncated to {len} bytes"));
    }
    let mut longer = blob.to_vec();
    for extra in 1..=16 {
        longer.push(if extra % 2 == 0 { 0 } else { 0xff });
        check_rejected(
            &longer,
            &mut storage,
            DecodeError::TrailingBytes { expected: total, got: total + extra },
            &format!("{extra} bytes appended"),
        );
    }
}

#[test]
fn solver_blob_every_bit_flip_is_rejected() {
    every_bit_flip_is_rejected(&solver_blob(), 1);
}

#[test]
fn solver_blob_every_truncation_is_rejected() {
    every_truncation_and_extension_is_rejected(&solver_blob());
}

/// The 8 kB reference blob: every truncation, every bit of the frame and of every 7th payload
/// byte (all of them would take ~20 s on a loaded 2-core machine for no new case: the solver
/// blob above already covers every bit).
#[test]
fn reference_blob_bit_flips_and_every_truncation_are_rejected() {
    let blob = reference_blob();
    every_bit_flip_is_rejected(&blob, 7);
    every_truncation_and_extension_is_rejected(&blob);
}

/// Every version other than the supported one, and every wrong magic byte value, is rejected
/// even when the checksum is recomputed to match (the header is checked before the CRC).
#[test]
fn wrong_version_or_magic_is_rejected_even_with_a_valid_checksum() {
    let blob = solver_blob();
    let mut storage = storage_for(&blob);
    let reseal = |b: &mut Vec<u8>| {
        let end = b.len() - TRAILER_LEN;
        let crc = crc32(&b[..end]);
        b[end..].copy_from_slice(&crc.to_le_bytes());
    };
    // The solver blob has no expansion: format 4.
    let own = u16::from_le_bytes([blob[4], blob[5]]);
    assert_eq!(own, FORMAT_WITHOUT_EXPANSION);
    let hamiltonian = MomentumLaw::Hamiltonian.first_format();
    for version in (0..=u16::MAX).step_by(97).chain([0, 2, 3, 5, 256, u16::MAX]) {
        if (hamiltonian..=own).contains(&version) {
            // Its own version, or an older one that holds the same model (format 3: no moments).
            continue;
        }
        let mut b = blob.clone();
        b[4..6].copy_from_slice(&version.to_le_bytes());
        reseal(&mut b);
        // An older version this build reads cannot hold the solver blob's (Hamiltonian) momentum law;
        // format 5 expects the expansion after the model, which a format-4 payload lacks.
        let expected = if (cbd_protocol::OLDEST_FORMAT_VERSION..hamiltonian).contains(&version) {
            DecodeError::Invalid(cbd_protocol::ModelError::OutOfRange { field: "momentum_law (not in this blob's format version)" })
        } else if (own..=FORMAT_VERSION).contains(&version) {
            DecodeError::Payload
        } else {
            DecodeError::UnsupportedVersion { found: version, supported: FORMAT_VERSION }
        };
        check_rejected(&b, &mut storage, expected, &format!("version {version}"));
    }
    for i in 0..4 {
        for v in 0..=255u8 {
            if v == MAGIC[i] {
                continue;
            }
            let mut b = blob.clone();
            b[i] = v;
            reseal(&mut b);
            check_rejected(&b, &mut storage, DecodeError::BadMagic, &format!("magic byte {i} = {v:#04x}"));
        }
    }
}

/// With the CRC repaired, a damaged payload is caught by the decoder or the validator (a flip
/// that yields a different but well-formed model cannot be detected by any checksum-free check).
/// Whatever happens, nothing panics and a model that loads evaluates to finite values or a typed error.
#[test]
fn resealed_payload_damage_never_panics() {
    let blob = solver_blob();
    let mut storage = storage_for(&blob);
    let end = blob.len() - TRAILER_LEN;
    let (mut payload_err, mut invalid, mut loaded) = (0, 0, 0);
    // Every bit of the payload's first 96 bytes (enum tags, varint lengths, kernel and integrator
    // fields), then one bit per byte over the arrays (each load integrates the flow: ~1 ms).
    for byte in HEADER_LEN..end {
        let bits = if byte < HEADER_LEN + 96 { 0..8 } else { (byte % 8) as u32..(byte % 8) as u32 + 1 };
        for bit in bits {
            let mut b = blob.clone();
            b[byte] ^= 1 << bit;
            let crc = crc32(&b[..end]);
            b[end..].copy_from_slice(&crc.to_le_bytes());
            let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| match Calibrator::load(&b, &mut storage) {
                Ok(mut cal) => {
                    let n = cal.model().n_joints();
                    for q in [[0.3, -1.2], [2.0, 5.5]] {
                        match cal.evaluate(&q[..n.min(2)]) {
                            Ok(e) => assert!(e.position().iter().all(|v| v.is_finite())),
                            Err(Error::NonFiniteResult) | Err(Error::QueryDimension { .. }) => {}
                            Err(e) => panic!("unexpected evaluate error {e:?}"),
                        }
                    }
                    1
                }
                Err(Error::Blob(DecodeError::Payload)) => 2,
                Err(Error::Blob(DecodeError::Invalid(_))) => 3,
                Err(Error::StorageTooSmall { .. }) | Err(Error::Diverged) => 3,
                Err(e) => panic!("unexpected load error {e:?}"),
            }));
            match result {
                Ok(1) => loaded += 1,
                Ok(2) => payload_err += 1,
                Ok(_) => invalid += 1,
                Err(_) => panic!("bit {bit} of byte {byte} (CRC resealed) panicked"),
            }
        }
    }
    eprintln!("resealed flips: {loaded} loaded (a different well-formed model), {payload_err} payload errors, {invalid} invalid models");
    // The header fields of the payload (enum tags, lengths, varints) are caught structurally.
    assert!(payload_err + invalid > 0, "loaded {loaded}, payload {payload_err}, invalid {invalid}");
}

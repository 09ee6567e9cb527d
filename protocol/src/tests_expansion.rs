//! Format 5: the expansion's round trip, its framing and its validation.

use crate::tests::{framed, le, sample_model};
use crate::*;
extern crate std;
use std::vec::Vec;

/// Planar RR (n = m = 2), Heun × 5 (10 stages): 3 joint and 2 task functions.
const CODES: [u8; 6] = [0, 0, 2, 5, 3, 0];
const EXPONENTS: [u8; 4] = [0, 0, 1, 2];

fn encode_vec(model: &Model<'_>) -> Result<Vec<u8>, EncodeError> {
    let mut buf = std::vec![0u8; 8192];
    let len = encode(model, &mut buf)?;
    buf.truncate(len);
    Ok(buf)
}

fn weights() -> Vec<u8> {
    le(&(0..10 * (3 * 2 + 2 * 2)).map(|i| (i as f64 * 0.37).sin() * 1e-3).collect::<Vec<_>>())
}

fn expansion<'a>(codes: &'a [u8], exponents: &'a [u8], weights: &'a [u8]) -> FieldExpansion<'a> {
    FieldExpansion {
        tolerance: 1e-12,
        task_radius: 2.5,
        n_joint_features: 3,
        joint_codes: codes,
        n_task_features: 2,
        task_exponents: exponents,
        weights: F64Slice::from_le_bytes(weights),
    }
}

#[test]
fn an_expansion_round_trips_in_format_5() {
    let (p, m, w) = (le(&[0.0, 0.1, 1.0, 1.1, 2.0, 2.1]), le(&[0.01, -0.02, 0.03, 0.0, -0.05, 0.5]), weights());
    let mut model = sample_model(&p, &m);
    model.expansion = Some(expansion(&CODES, &EXPONENTS, &w));
    let blob = encode_vec(&model).unwrap();
    assert_eq!(u16::from_le_bytes([blob[4], blob[5]]), 5);
    let back = decode(&blob).unwrap();
    assert_eq!(back, model);
    assert_eq!(back.expansion.as_ref().unwrap().weights.get(99), w.chunks(8).nth(99).map(|c| f64::from_le_bytes(c.try_into().unwrap())));
    // Without the expansion the same model is format 4, and its bytes are those of the model alone.
    model.expansion = None;
    let blob4 = encode_vec(&model).unwrap();
    assert_eq!(u16::from_le_bytes([blob4[4], blob4[5]]), 4);
    assert_eq!(blob4, framed(&model, 4));
    assert_eq!(decode(&blob4).unwrap().expansion, None);
}

/// A format-5 payload: the model, then the postcard encoding of `expansion`.
fn framed5(model: &Model<'_>, expansion: &Option<FieldExpansion<'_>>, version: u16) -> Vec<u8> {
    let mut payload = postcard::to_allocvec(model).unwrap();
    payload.extend_from_slice(&postcard::to_allocvec(expansion).unwrap());
    let mut blob = Vec::new();
    blob.extend_from_slice(&MAGIC);
    blob.extend_from_slice(&version.to_le_bytes());
    blob.extend_from_slice(&(payload.len() as u32).to_le_bytes());
    blob.extend_from_slice(&payload);
    let crc = CRC32.checksum(&blob);
    blob.extend_from_slice(&crc.to_le_bytes());
    blob
}

#[test]
fn the_version_decides_whether_the_tail_is_read() {
    let (p, m, w) = (le(&[0.0, 0.1, 1.0, 1.1, 2.0, 2.1]), le(&[0.01, -0.02, 0.03, 0.0, -0.05, 0.5]), weights());
    let model = sample_model(&p, &m);
    let e = Some(expansion(&CODES, &EXPONENTS, &w));
    // A format-5 blob whose tail is `None` is the model without expansion.
    assert_eq!(decode(&framed5(&model, &None, 5)), Ok(model.clone()));
    // Format 5 needs the tail; formats 2–4 refuse one (trailing payload bytes).
    assert_eq!(decode(&framed(&model, 5)), Err(DecodeError::Payload));
    for version in [3, 4] {
        assert_eq!(decode(&framed5(&model, &e, version)), Err(DecodeError::Payload), "version {version}");
        assert_eq!(decode(&framed5(&model, &None, version)), Err(DecodeError::Payload), "version {version}");
    }
    let mut with = model.clone();
    with.expansion = e.clone();
    assert_eq!(decode(&framed5(&model, &e, 5)), Ok(with));
}

#[test]
fn every_single_bit_flip_of_an_expansion_blob_is_rejected() {
    let (p, m, w) = (le(&[0.0, 0.1, 1.0, 1.1, 2.0, 2.1]), le(&[0.01, -0.02, 0.03, 0.0, -0.05, 0.5]), weights());
    let mut model = sample_model(&p, &m);
    model.expansion = Some(expansion(&CODES, &EXPONENTS, &w));
    let blob = encode_vec(&model).unwrap();
    let tail_start = blob.len() - TRAILER_LEN - w.len() - 40;
    for byte in 0..blob.len() {
        for bit in 0..8 {
            let mut bad = blob.clone();
            bad[byte] ^= 1 << bit;
            let err = decode(&bad).expect_err("a flipped bit must not load");
            let expected_kind = match byte {
                0..=3 => matches!(err, DecodeError::BadMagic),
                4..=5 => matches!(err, DecodeError::UnsupportedVersion { .. } | DecodeError::ChecksumMismatch { .. }),
                6..=9 => matches!(err, DecodeError::Truncated { .. } | DecodeError::TrailingBytes { .. }),
                _ => matches!(err, DecodeError::ChecksumMismatch { .. }),
            };
            assert!(expected_kind, "byte {byte} bit {bit} (expansion from {tail_start}): unexpected error {err:?}");
        }
    }
}

#[test]
fn every_invalid_expansion_is_named() {
    let (p, m, w) = (le(&[0.0, 0.1, 1.0, 1.1, 2.0, 2.1]), le(&[0.01, -0.02, 0.03, 0.0, -0.05, 0.5]), weights());
    let model = sample_model(&p, &m);
    let check = |e: FieldExpansion<'_>, expected: ModelError| {
        let mut bad = model.clone();
        bad.expansion = Some(e);
        assert_eq!(bad.validate(), Err(expected));
        let mut buf = [0u8; 4096];
        assert_eq!(encode(&bad, &mut buf), Err(EncodeError::Invalid(expected)));
        // Framed by hand, the decoder refuses it too.
        let e = bad.expansion.take();
        assert_eq!(decode(&framed5(&bad, &e, 5)), Err(DecodeError::Invalid(expected)));
    };
    let good = || expansion(&CODES, &EXPONENTS, &w);
    let range = |field| ModelError::OutOfRange { field };
    for t in [0.0, 1.0, -1e-3] {
        check(FieldExpansion { tolerance: t, ..good() }, range("expansion.tolerance"));
    }
    check(FieldExpansion { tolerance: f64::NAN, ..good() }, ModelError::NonFinite { field: "expansion.tolerance", index: 0 });
    check(FieldExpansion { task_radius: 0.0, ..good() }, range("expansion.task_radius"));
    check(FieldExpansion { task_radius: f64::INFINITY, ..good() }, ModelError::NonFinite { field: "expansion.task_radius", index: 0 });
    check(FieldExpansion { n_joint_features: MAX_EXPANSION_FEATURES + 1, ..good() }, range("expansion.n_joint_features"));
    check(FieldExpansion { n_task_features: MAX_EXPANSION_FEATURES + 1, ..good() }, range("expansion.n_task_features"));
    check(
        FieldExpansion { n_joint_features: 2, ..good() },
        ModelError::Dimension { field: "expansion.joint_codes", expected: 4, found: 6 },
    );
    check(
        FieldExpansion { joint_codes: &CODES[..4], n_joint_features: 2, ..good() },
        ModelError::Dimension { field: "expansion.weights", expected: 8 * 10 * (2 * 2 + 2 * 2), found: w.len() },
    );
    check(
        FieldExpansion { n_task_features: 1, ..good() },
        ModelError::Dimension { field: "expansion.task_exponents", expected: 2, found: 4 },
    );
    check(
        FieldExpansion { weights: F64Slice::from_le_bytes(&w[..w.len() - 1]), ..good() },
        ModelError::Dimension { field: "expansion.weights", expected: w.len(), found: w.len() - 1 },
    );
    let codes = [0, 0, 2, (MAX_EXPANSION_ORDER + 1) << 1, 3, 0];
    check(FieldExpansion { joint_codes: &codes, ..good() }, ModelError::OutOfRangeAt { field: "expansion.joint_codes (order)", index: 3 });
    let codes = [0, 0, 2, 1, 3, 0];
    check(FieldExpansion { joint_codes: &codes, ..good() }, ModelError::OutOfRangeAt { field: "expansion.joint_codes (sin 0x)", index: 3 });
    let exponents = [0, 0, 1, MAX_EXPANSION_ORDER + 1];
    check(
        FieldExpansion { task_exponents: &exponents, ..good() },
        ModelError::OutOfRangeAt { field: "expansion.task_exponents", index: 3 },
    );
    let mut values: Vec<f64> = w.chunks(8).map(|c| f64::from_le_bytes(c.try_into().unwrap())).collect();
    values[17] = f64::NAN;
    let nan = le(&values);
    check(
        FieldExpansion { weights: F64Slice::from_le_bytes(&nan), ..good() },
        ModelError::NonFinite { field: "expansion.weights", index: 17 },
    );
    // The highest order is allowed, and so is an empty basis.
    let codes = [0, 0, 2, MAX_EXPANSION_ORDER << 1 | 1, 3, 0];
    let mut ok = model.clone();
    ok.expansion = Some(FieldExpansion { joint_codes: &codes, ..good() });
    assert_eq!(ok.validate(), Ok(()));
}

#[test]
fn a_sine_on_a_gaussian_axis_is_refused() {
    let (p, m) = (le(&[0.0, 0.1, 1.0, 1.1, 2.0, 2.1]), le(&[0.01, -0.02, 0.03, 0.0, -0.05, 0.5]));
    let mut model = sample_model(&p, &m);
    // A DH chain with a prismatic second joint and a Gaussian kernel on it.
    let joint = |kind| DhJoint { kind, a: 0.5, alpha: 0.0, d: 0.0, theta_offset: 0.0 };
    model.nominal = NominalModel::DhChain(DhChain {
        convention: DhConvention::Standard,
        joints: heapless::Vec::from_slice(&[joint(JointKind::Revolute), joint(JointKind::Prismatic)]).unwrap(),
        base: Transform::IDENTITY,
        tool: Transform::IDENTITY,
        effects: Effects::NONE,
        tool_points: heapless::Vec::new(),
    });
    model.joint_kernel.axes =
        heapless::Vec::from_slice(&[JointKernelAxis::Periodic { b: 1.0 }, JointKernelAxis::Gaussian { width: 0.3 }]).unwrap();
    let m3 = le(&[0.0; 9]);
    model.momenta = F64Slice::from_le_bytes(&m3);
    let w = le(&[0.0; 10 * (2 * 2 + 1 * 3)]);
    let exponents = [0, 1, 2];
    let ok_codes = [4, 6, 3, 0];
    let mut e = FieldExpansion {
        tolerance: 1e-9,
        task_radius: 1.0,
        n_joint_features: 2,
        joint_codes: &ok_codes,
        n_task_features: 1,
        task_exponents: &exponents,
        weights: F64Slice::from_le_bytes(&w),
    };
    model.expansion = Some(e.clone());
    assert_eq!(model.validate(), Ok(()));
    let bad_codes = [4, 7, 3, 0];
    e.joint_codes = &bad_codes;
    model.expansion = Some(e);
    assert_eq!(model.validate(), Err(ModelError::OutOfRangeAt { field: "expansion.joint_codes (sine on a Gaussian axis)", index: 1 }));
}

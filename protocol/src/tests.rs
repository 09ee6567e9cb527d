use super::*;
extern crate std;
use std::vec::Vec;

fn le(values: &[f64]) -> Vec<u8> {
    values.iter().flat_map(|v| v.to_le_bytes()).collect()
}

fn sample_model<'a>(points: &'a [u8], momenta: &'a [u8]) -> Model<'a> {
    Model {
        nominal: NominalModel::planar(&[1.0, 0.5]).unwrap(),
        normalisation: Normalisation::IDENTITY,
        joint_kernel: JointKernel { gamma: 8.0, axes: heapless::Vec::from_slice(&[JointKernelAxis::Periodic { b: 1.0186 }; 2]).unwrap() },
        task_kernel: TaskKernel { width: 1.027 },
        integrator: Integrator { method: IntegratorMethod::Heun, steps: 5 },
        momentum_law: MomentumLaw::WithDivergence,
        sigma: 1e-3,
        n_points: 3,
        points: F64Slice::from_le_bytes(points),
        momenta: F64Slice::from_le_bytes(momenta),
    }
}

fn sample_blob() -> Vec<u8> {
    let p = le(&[0.0, 0.1, 1.0, 1.1, 2.0, 2.1]);
    let m = le(&[0.01, -0.02, 0.03, 0.0, -0.05, 0.5]);
    let mut buf = [0u8; 1024];
    let len = encode(&sample_model(&p, &m), &mut buf).unwrap();
    buf[..len].to_vec()
}

#[test]
fn round_trip_keeps_every_field() {
    let p = le(&[0.0, 0.1, 1.0, 1.1, 2.0, 2.1]);
    let m = le(&[0.01, -0.02, 0.03, 0.0, -0.05, 0.5]);
    let model = sample_model(&p, &m);
    let mut buf = [0u8; 1024];
    let len = encode(&model, &mut buf).unwrap();
    let back = decode(&buf[..len]).unwrap();
    assert_eq!(back, model);
    assert_eq!(back.points.get(3), Some(1.1));
    assert_eq!(back.momenta.get(5), Some(0.5));
}

#[test]
fn encoding_is_deterministic() {
    assert_eq!(sample_blob(), sample_blob());
}

#[test]
fn every_single_bit_flip_is_rejected() {
    let blob = sample_blob();
    for byte in 0..blob.len() {
        for bit in 0..8 {
            let mut bad = blob.clone();
            bad[byte] ^= 1 << bit;
            let err = decode(&bad).expect_err("a flipped bit must not load");
            let expected_kind = match byte {
                0..=3 => matches!(err, DecodeError::BadMagic),
                4..=5 => matches!(err, DecodeError::UnsupportedVersion { .. }),
                6..=9 => matches!(err, DecodeError::Truncated { .. } | DecodeError::TrailingBytes { .. }),
                _ => matches!(err, DecodeError::ChecksumMismatch { .. }),
            };
            assert!(expected_kind, "byte {byte} bit {bit}: unexpected error {err:?}");
        }
    }
}

#[test]
fn every_truncation_is_rejected() {
    let blob = sample_blob();
    for len in 0..blob.len() {
        let err = decode(&blob[..len]).expect_err("a truncated blob must not load");
        assert!(matches!(err, DecodeError::Truncated { .. }), "length {len}: {err:?}");
    }
    let mut longer = blob.clone();
    longer.push(0);
    assert!(matches!(decode(&longer), Err(DecodeError::TrailingBytes { .. })));
}

#[test]
fn wrong_version_is_named() {
    let mut blob = sample_blob();
    blob[4..6].copy_from_slice(&(FORMAT_VERSION + 1).to_le_bytes());
    assert_eq!(decode(&blob), Err(DecodeError::UnsupportedVersion { found: FORMAT_VERSION + 1, supported: FORMAT_VERSION }));
}

#[test]
fn invalid_models_are_not_encoded() {
    let p = le(&[0.0, 0.1, 1.0, 1.1, 2.0, 2.1]);
    let m = le(&[0.01, -0.02, 0.03, 0.0, -0.05, f64::NAN]);
    let mut buf = [0u8; 1024];
    assert_eq!(encode(&sample_model(&p, &m), &mut buf), Err(EncodeError::Invalid(ModelError::NonFinite { field: "momenta", index: 5 })));
    let short = le(&[0.0, 0.1, 1.0]);
    let m = le(&[0.0; 6]);
    assert!(matches!(
        encode(&sample_model(&short, &m), &mut buf),
        Err(EncodeError::Invalid(ModelError::Dimension { field: "points", .. }))
    ));
    let p = le(&[0.0; 6]);
    let mut model = sample_model(&p, &m);
    model.task_kernel.width = 0.0;
    assert_eq!(encode(&model, &mut buf), Err(EncodeError::Invalid(ModelError::OutOfRange { field: "task_kernel.width" })));
}

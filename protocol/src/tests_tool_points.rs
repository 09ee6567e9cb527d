//! Format 6: the tool points' round trip, their framing and their validation.

use crate::tests::{framed, le};
use crate::*;
extern crate std;
use std::vec::Vec;

/// The UR5 (mm) with 2 poses × `tool_points.len().max(1)` control points.
fn ur5_model<'a>(tool_points: &[[f64; 3]], points: &'a [u8], momenta: &'a [u8]) -> Model<'a> {
    let mut chain = ur5::chain();
    chain.tool_points = heapless::Vec::from_slice(tool_points).unwrap();
    let nominal = NominalModel::DhChain(chain);
    Model {
        n_points: (2 * nominal.tool_point_count()) as u32,
        nominal,
        normalisation: Normalisation { task_offset: [0.0, 100.0, 200.0], task_scale: 500.0 },
        joint_kernel: JointKernel { gamma: 0.5, axes: heapless::Vec::from_slice(&[JointKernelAxis::Periodic { b: 1.5 }; 6]).unwrap() },
        task_kernel: TaskKernel { width: 0.8 },
        integrator: Integrator { method: IntegratorMethod::Heun, steps: 2 },
        momentum_law: MomentumLaw::Hamiltonian,
        sigma: 1e-3,
        points: F64Slice::from_le_bytes(points),
        momenta: F64Slice::from_le_bytes(momenta),
        expansion: None,
        noise_sigma: None,
        configuration_kernel: None,
        drift: None,
        provenance: None,
    }
}

fn arrays(n_points: usize) -> (Vec<u8>, Vec<u8>) {
    let p: Vec<f64> = (0..n_points * 6).map(|i| ((i / (6 * (n_points / 2))) as f64 + 1.0) * 0.1 * (i % 6) as f64).collect();
    let m: Vec<f64> = (0..n_points * 3).map(|i| (i as f64 * 0.7).sin() * 1e-3).collect();
    (le(&p), le(&m))
}

const THREE: [[f64; 3]; 3] = [[0.0, 0.0, 0.0], [100.0, 0.0, 0.0], [0.0, 100.0, 0.0]];

fn encode_vec(model: &Model<'_>) -> Result<Vec<u8>, EncodeError> {
    let mut buf = std::vec![0u8; 8192];
    let len = encode(model, &mut buf)?;
    buf.truncate(len);
    Ok(buf)
}

/// A format-6 payload by hand: the model, `None` expansion, then the count and the raw values.
fn framed6(model: &Model<'_>, count: u8, values: &[f64]) -> Vec<u8> {
    let mut payload = postcard::to_allocvec(model).unwrap();
    payload.extend_from_slice(&postcard::to_allocvec(&model.expansion).unwrap());
    payload.push(count);
    payload.extend_from_slice(&le(values));
    let mut blob = Vec::new();
    blob.extend_from_slice(&MAGIC);
    blob.extend_from_slice(&6u16.to_le_bytes());
    blob.extend_from_slice(&(payload.len() as u32).to_le_bytes());
    blob.extend_from_slice(&payload);
    let crc = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC).checksum(&blob);
    blob.extend_from_slice(&crc.to_le_bytes());
    blob
}

#[test]
fn tool_points_round_trip_in_format_6() {
    let (p, m) = arrays(6);
    let model = ur5_model(&THREE, &p, &m);
    assert_eq!(model.nominal.tool_point_count(), 3);
    assert_eq!(model.nominal.tool_point(1), Some([100.0, 0.0, 0.0]));
    assert_eq!(model.nominal.tool_point(3), None);
    let blob = encode_vec(&model).unwrap();
    assert_eq!(u16::from_le_bytes([blob[4], blob[5]]), 6);
    assert_eq!(format_for(&model), 6);
    let back = decode(&blob).unwrap();
    assert_eq!(back, model);
    assert_eq!(back.nominal.tool_points(), &THREE);
    // The format-6 layout is the model, `None`, then postcard's own encoding of the list.
    let mut chain_points: heapless::Vec<[f64; 3], MAX_TOOL_POINTS> = heapless::Vec::new();
    chain_points.extend_from_slice(&THREE).unwrap();
    let tail = postcard::to_allocvec(&chain_points).unwrap();
    assert_eq!(&blob[blob.len() - TRAILER_LEN - tail.len()..blob.len() - TRAILER_LEN], &tail[..]);
    assert_eq!(blob, framed6(&model, 3, &THREE.concat()));
    // Every bit flip and every truncation is refused.
    for byte in 0..blob.len() {
        let mut bad = blob.clone();
        bad[byte] ^= 0x10;
        assert!(decode(&bad).is_err(), "byte {byte}");
    }
    for len in 0..blob.len() {
        assert!(decode(&blob[..len]).is_err());
    }
}

#[test]
fn a_model_without_tool_points_keeps_its_format_and_bytes() {
    let (p, m) = arrays(2);
    let model = ur5_model(&[], &p, &m);
    assert_eq!(model.nominal.tool_point_count(), 1);
    assert_eq!(model.nominal.tool_point(0), Some([0.0; 3]));
    assert_eq!(model.nominal.tool_point(1), None);
    let blob = encode_vec(&model).unwrap();
    assert_eq!(blob, framed(&model, FORMAT_WITHOUT_EXPANSION));
    assert_eq!(decode(&blob).unwrap(), model);
    // Planar chains: one point.
    let planar = NominalModel::planar(&[1.0, 0.5]).unwrap();
    assert_eq!((planar.tool_point_count(), planar.tool_point(0), planar.tool_point(1)), (1, Some([0.0; 3]), None));
    // A format-6 header over an empty list is the same model; formats 4 and 5 refuse the tail.
    assert_eq!(decode(&framed6(&model, 0, &[])), Ok(model.clone()));
    let (p6, m6) = arrays(6);
    let with = ur5_model(&THREE, &p6, &m6);
    let mut hand = framed6(&with, 3, &THREE.concat());
    hand[4] = 5;
    let crc = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC).checksum(&hand[..hand.len() - 4]);
    let n = hand.len();
    hand[n - 4..].copy_from_slice(&crc.to_le_bytes());
    assert_eq!(decode(&hand), Err(DecodeError::Payload));
}

#[test]
fn bad_tool_points_are_named() {
    let (p, m) = arrays(6);
    let check = |points: [[f64; 3]; 3], expected: ModelError| {
        let model = ur5_model(&points, &p, &m);
        assert_eq!(model.validate(), Err(expected));
        assert_eq!(encode_vec(&model), Err(EncodeError::Invalid(expected)));
        assert_eq!(decode(&framed6(&model, 3, &points.concat())), Err(DecodeError::Invalid(expected)));
    };
    let mut nan = THREE;
    nan[1][2] = f64::NAN;
    check(nan, ModelError::NonFinite { field: "nominal.tool_points", index: 5 });
    let mut far = THREE;
    far[2][0] = -2.0 * MAX_TOOL_POINT_COORDINATE;
    check(far, ModelError::OutOfRangeAt { field: "nominal.tool_points (beyond MAX_TOOL_POINT_COORDINATE)", index: 6 });
    // n_points must be a whole number of poses.
    let (p4, m4) = arrays(4);
    let mut model = ur5_model(&THREE, &p4, &m4);
    model.n_points = 4;
    assert_eq!(model.validate(), Err(ModelError::OutOfRange { field: "n_points (not a multiple of the tool points)" }));
    // More than MAX_TOOL_POINTS in a blob: named, not a bare payload error.
    let model = ur5_model(&THREE, &p, &m);
    let five = [1.0; 15];
    assert_eq!(
        decode(&framed6(&model, 5, &five)),
        Err(DecodeError::Invalid(ModelError::Dimension { field: "nominal.tool_points (at most MAX_TOOL_POINTS)", expected: 4, found: 5 }))
    );
    // Fewer values than the count: a payload error.
    assert_eq!(decode(&framed6(&model, 3, &THREE.concat()[..8])), Err(DecodeError::Payload));
    // Tool points on a planar chain cannot be written; a hand-made blob is refused by name.
    let (pp, mp) = (le(&[0.0, 0.1, 1.0, 1.1, 2.0, 2.1]), le(&[0.01, -0.02, 0.03, 0.0, -0.05, 0.5]));
    let planar = crate::tests::sample_model(&pp, &mp);
    assert_eq!(
        decode(&framed6(&planar, 1, &[1.0, 2.0, 3.0])),
        Err(DecodeError::Invalid(ModelError::OutOfRange { field: "nominal.tool_points (on a planar chain)" }))
    );
}

/// Issue 39 case 3: a blob whose tool-point count regroups its rows (2 or 4 points over data of
/// 3 per pose, a valid checksum) evaluated every row as the wrong point. The control points of a
/// pose share one configuration; a count that breaks that is refused by name.
#[test]
fn a_tool_point_count_that_regroups_the_poses_is_refused() {
    let (p, m) = arrays(6);
    for points in [&THREE[..2], &[THREE[0], THREE[1], THREE[2], [5.0, 5.0, 5.0]][..]] {
        let mut model = ur5_model(points, &p, &m);
        model.n_points = 6;
        if points.len() == 4 {
            // 4 does not divide 6: the count check names it first; 8 control points of 2 poses × 3 …
            assert!(matches!(encode_vec(&model), Err(EncodeError::Invalid(ModelError::OutOfRange { .. }))));
            continue;
        }
        let e = encode_vec(&model).unwrap_err();
        assert_eq!(
            e,
            EncodeError::Invalid(ModelError::OutOfRangeAt { field: "points (a pose's tool points at different configurations)", index: 3 })
        );
    }
    // … and 4 points over 3 poses of 4 rows read from data of 3 points per pose (12 = 4 poses × 3).
    let q: Vec<f64> = (0..12).flat_map(|c| [(c / 3) as f64 * 0.1; 6]).collect();
    let (p, m) = (le(&q), le(&[1e-3; 36]));
    let four = [THREE[0], THREE[1], THREE[2], [5.0, 5.0, 5.0]];
    let mut model = ur5_model(&four, &p, &m);
    model.n_points = 12;
    assert!(matches!(encode_vec(&model), Err(EncodeError::Invalid(ModelError::OutOfRangeAt { index: 3, .. }))));
    let mut model = ur5_model(&THREE, &p, &m);
    model.n_points = 12;
    encode_vec(&model).unwrap();
}

/// Issue 39 case 13: crafted blobs (valid checksum) with a scaled, sheared or mirrored base or tool
/// rotation evaluated to 1.3e24 mm. A rotation must be orthonormal within 1e-9 with det +1.
#[test]
fn base_and_tool_must_be_rotations() {
    let (p, m) = arrays(2);
    let fine = ur5_model(&[], &p, &m);
    let NominalModel::DhChain(chain) = &fine.nominal else { unreachable!() };
    let identity = Transform::IDENTITY.rotation;
    let turned = [0.0, -1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0];
    let scaled = identity.map(|v| v * (1.0 + 1e-8));
    let mirrored = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, -1.0];
    let nearly = [1.0 + 2e-10, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0];
    for (rotation, ok) in [(turned, true), (nearly, true), (scaled, false), (mirrored, false), ([0.0; 9], false)] {
        for tool in [false, true] {
            let mut c = chain.clone();
            let t = if tool { &mut c.tool } else { &mut c.base };
            t.rotation = rotation;
            let model = Model { nominal: NominalModel::DhChain(c), ..fine.clone() };
            let mut buf = [0u8; 4096];
            match encode(&model, &mut buf) {
                Ok(_) => assert!(ok, "{rotation:?} accepted"),
                Err(EncodeError::Invalid(ModelError::OutOfRange { field })) => {
                    assert!(!ok && field.contains(if tool { "nominal.tool.rotation" } else { "nominal.base.rotation" }), "{field}")
                }
                Err(e) => panic!("{e:?}"),
            }
        }
    }
}

use super::*;
use crate::codec::{payload_error, CRC32};
extern crate std;
use std::vec::Vec;

pub(crate) fn le(values: &[f64]) -> Vec<u8> {
    values.iter().flat_map(|v| v.to_le_bytes()).collect()
}

pub(crate) fn sample_model<'a>(points: &'a [u8], momenta: &'a [u8]) -> Model<'a> {
    Model {
        nominal: NominalModel::planar(&crate::paper_rr::LENGTHS).unwrap(),
        normalisation: Normalisation::IDENTITY,
        joint_kernel: crate::paper_rr::joint_kernel(),
        task_kernel: crate::paper_rr::task_kernel(),
        integrator: Integrator { method: IntegratorMethod::Heun, steps: 5 },
        momentum_law: MomentumLaw::WithDivergence,
        sigma: 1e-3,
        n_points: 3,
        points: F64Slice::from_le_bytes(points),
        momenta: F64Slice::from_le_bytes(momenta),
        expansion: None,
        noise_sigma: None,
        configuration_kernel: None,
        drift: None,
        provenance: None,
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
                // A flip to another version is unsupported or, if readable, caught by the checksum.
                4..=5 => matches!(err, DecodeError::UnsupportedVersion { .. } | DecodeError::ChecksumMismatch { .. }),
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

fn with_effects(effects: Effects, check: impl Fn(Result<usize, EncodeError>)) {
    let p = le(&[0.0, 0.1, 1.0, 1.1, 2.0, 2.1]);
    let m = le(&[0.0; 6]);
    let mut model = sample_model(&p, &m);
    *model.nominal.effects_mut() = effects;
    let mut buf = [0u8; 2048];
    check(encode(&model, &mut buf));
}

fn effects_of(list: &[Effect]) -> Effects {
    Effects { gravity: GravityModel::PLANAR, list: heapless::Vec::from_slice(list).unwrap() }
}

#[test]
fn valid_effects_round_trip() {
    let gravity = GravityModel { direction: [0.6, -0.8, 0.0], link_masses: heapless::Vec::from_slice(&[2.0, 0.0]).unwrap() };
    let effects = Effects {
        gravity,
        list: heapless::Vec::from_slice(&[
            Effect::EncoderScale { joint: 0, scale: 1e-3 },
            Effect::Transmission { joint: 1, harmonic: 16, cos: 1e-3, sin: -2e-3 },
            Effect::GravityCompliance { joint: 1, compliance: 0.01 },
            Effect::LinkBending { link: 1, compliance: -0.02 },
        ])
        .unwrap(),
    };
    let p = le(&[0.0, 0.1, 1.0, 1.1, 2.0, 2.1]);
    let m = le(&[0.0; 6]);
    let mut model = sample_model(&p, &m);
    *model.nominal.effects_mut() = effects;
    let mut buf = [0u8; 2048];
    let len = encode(&model, &mut buf).unwrap();
    assert_eq!(decode(&buf[..len]).unwrap(), model);
}

#[test]
fn every_invalid_effect_is_named() {
    let invalid = |field: &'static str, index: usize| {
        move |r: Result<usize, EncodeError>| {
            assert_eq!(r, Err(EncodeError::Invalid(ModelError::OutOfRangeAt { field, index })));
        }
    };
    let non_finite = |field: &'static str, index: usize| {
        move |r: Result<usize, EncodeError>| {
            assert_eq!(r, Err(EncodeError::Invalid(ModelError::NonFinite { field, index })));
        }
    };
    let ok = Effect::EncoderScale { joint: 1, scale: 0.0 };
    // Joint and link indices below n_joints (= 2), reported with the effect's position in the list.
    with_effects(effects_of(&[ok, Effect::EncoderScale { joint: 2, scale: 0.0 }]), invalid("nominal.effects.list.EncoderScale.joint", 1));
    with_effects(
        effects_of(&[Effect::Transmission { joint: 7, harmonic: 1, cos: 0.0, sin: 0.0 }]),
        invalid("nominal.effects.list.Transmission.joint", 0),
    );
    with_effects(
        effects_of(&[ok, ok, Effect::GravityCompliance { joint: 255, compliance: 0.0 }]),
        invalid("nominal.effects.list.GravityCompliance.joint", 2),
    );
    with_effects(effects_of(&[Effect::LinkBending { link: 2, compliance: 0.0 }]), invalid("nominal.effects.list.LinkBending.link", 0));
    // Harmonics 1..=16.
    for h in [0, 17, 255] {
        with_effects(
            effects_of(&[Effect::Transmission { joint: 0, harmonic: h, cos: 0.0, sin: 0.0 }]),
            invalid("nominal.effects.list.Transmission.harmonic", 0),
        );
    }
    with_effects(effects_of(&[Effect::Transmission { joint: 0, harmonic: 1, cos: 0.0, sin: 0.0 }]), |r| assert!(r.is_ok()));
    // Every value finite.
    for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
        with_effects(
            effects_of(&[Effect::EncoderScale { joint: 0, scale: bad }]),
            non_finite("nominal.effects.list.EncoderScale.scale", 0),
        );
        with_effects(
            effects_of(&[ok, Effect::Transmission { joint: 0, harmonic: 2, cos: bad, sin: 0.0 }]),
            non_finite("nominal.effects.list.Transmission.cos", 1),
        );
        with_effects(
            effects_of(&[Effect::Transmission { joint: 0, harmonic: 2, cos: 0.0, sin: bad }]),
            non_finite("nominal.effects.list.Transmission.sin", 0),
        );
        with_effects(
            effects_of(&[Effect::GravityCompliance { joint: 0, compliance: bad }]),
            non_finite("nominal.effects.list.GravityCompliance.compliance", 0),
        );
        with_effects(
            effects_of(&[Effect::LinkBending { link: 0, compliance: bad }]),
            non_finite("nominal.effects.list.LinkBending.compliance", 0),
        );
    }
    // Link masses: empty or one per joint, finite, ≥ 0.
    let masses = |m: &[f64]| Effects {
        gravity: GravityModel { direction: [0.0, -1.0, 0.0], link_masses: heapless::Vec::from_slice(m).unwrap() },
        list: heapless::Vec::new(),
    };
    with_effects(masses(&[1.0]), |r| {
        assert_eq!(
            r,
            Err(EncodeError::Invalid(ModelError::Dimension { field: "nominal.effects.gravity.link_masses", expected: 2, found: 1 }))
        )
    });
    with_effects(masses(&[1.0, 1.0, 1.0]), |r| {
        assert_eq!(
            r,
            Err(EncodeError::Invalid(ModelError::Dimension { field: "nominal.effects.gravity.link_masses", expected: 2, found: 3 }))
        )
    });
    with_effects(masses(&[1.0, f64::NAN]), non_finite("nominal.effects.gravity.link_masses", 1));
    with_effects(masses(&[f64::INFINITY, 1.0]), non_finite("nominal.effects.gravity.link_masses", 0));
    with_effects(masses(&[1.0, -1e-300]), invalid("nominal.effects.gravity.link_masses (negative)", 1));
    with_effects(masses(&[0.0, 0.0]), |r| assert!(r.is_ok()));
    with_effects(masses(&[]), |r| assert!(r.is_ok()));
    // Gravity direction finite and of unit length within 1e-9.
    let direction =
        |d: [f64; 3]| Effects { gravity: GravityModel { direction: d, link_masses: heapless::Vec::new() }, list: heapless::Vec::new() };
    with_effects(direction([0.0, f64::NAN, 0.0]), non_finite("nominal.effects.gravity.direction", 1));
    with_effects(direction([0.0, 0.0, f64::NEG_INFINITY]), non_finite("nominal.effects.gravity.direction", 2));
    let not_unit = |r: Result<usize, EncodeError>| {
        assert_eq!(r, Err(EncodeError::Invalid(ModelError::OutOfRange { field: "nominal.effects.gravity.direction (not unit length)" })))
    };
    with_effects(direction([0.0, 0.0, 0.0]), not_unit);
    with_effects(direction([0.0, -1.0 - 2e-9, 0.0]), not_unit);
    with_effects(direction([0.0, -1.0 + 2e-9, 0.0]), not_unit);
    with_effects(direction([0.6, 0.8, 1e-4]), not_unit);
    with_effects(direction([0.0, -1.0 - 5e-10, 0.0]), |r| assert!(r.is_ok()));
    with_effects(direction([0.6, 0.0, -0.8]), |r| assert!(r.is_ok()));
}

#[test]
fn a_blob_with_an_invalid_effect_does_not_decode() {
    // Framed by hand (encode refuses it): decode must validate the effects too.
    let p = le(&[0.0, 0.1, 1.0, 1.1, 2.0, 2.1]);
    let m = le(&[0.0; 6]);
    let mut model = sample_model(&p, &m);
    model.nominal.effects_mut().list.push(Effect::GravityCompliance { joint: 2, compliance: 1e-3 }).unwrap();
    let blob = framed(&model, FORMAT_WITHOUT_EXPANSION);
    assert_eq!(
        decode(&blob),
        Err(DecodeError::Invalid(ModelError::OutOfRangeAt { field: "nominal.effects.list.GravityCompliance.joint", index: 0 }))
    );
}

/// A blob framed by hand with `version` in its header (encode always writes the current one).
pub(crate) fn framed(model: &Model<'_>, version: u16) -> Vec<u8> {
    let payload = postcard::to_allocvec(model).unwrap();
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
fn format_2_blobs_still_load_and_cannot_hold_the_hamiltonian_laws() {
    let p = le(&[0.0, 0.1, 1.0, 1.1, 2.0, 2.1]);
    let m = le(&[0.01, -0.02, 0.03, 0.0, -0.05, 0.5]);
    let mut model = sample_model(&p, &m);
    // The payload of a format-2 law is the same bytes in format 2 and 3.
    assert_eq!(decode(&framed(&model, 2)), Ok(model.clone()));
    assert_eq!(decode(&framed(&model, 3)), Ok(model.clone()));
    for law in [MomentumLaw::Hamiltonian, MomentumLaw::HamiltonianWithoutDivergence] {
        model.momentum_law = law;
        assert_eq!(decode(&framed(&model, 3)), Ok(model.clone()));
        assert!(matches!(decode(&framed(&model, 2)), Err(DecodeError::Invalid(ModelError::OutOfRange { .. }))), "{law:?}");
    }
    assert_eq!(decode(&framed(&model, 1)), Err(DecodeError::UnsupportedVersion { found: 1, supported: FORMAT_VERSION }));
}

#[test]
fn the_flow_kernel_carries_the_laws_sign_exactly() {
    let k = JointKernel { gamma: 8.0, axes: heapless::Vec::from_slice(&[JointKernelAxis::Periodic { b: 1.0 }; 2]).unwrap() };
    assert_eq!(k.for_flow(MomentumLaw::WithDivergence), k);
    assert_eq!(k.for_flow(MomentumLaw::Hamiltonian).gamma.to_bits(), (-8.0f64).to_bits());
    assert!(MomentumLaw::Hamiltonian.has_divergence() && !MomentumLaw::HamiltonianWithoutDivergence.has_divergence());
}

fn with_gravity_moment<'a>(p: &'a [u8], m: &'a [u8]) -> Model<'a> {
    let mut model = sample_model(p, m);
    let effects = model.nominal.effects_mut();
    effects.list.push(Effect::GravityCompliance { joint: 0, compliance: 2e-3 }).unwrap();
    effects.list.push(Effect::GravityMoment { joint: 0, link: 1, mass: 0.8, first_moment: [-0.1, 0.02, 0.0] }).unwrap();
    model
}

#[test]
fn format_3_blobs_still_load_and_cannot_hold_a_gravity_moment() {
    let p = le(&[0.0, 0.1, 1.0, 1.1, 2.0, 2.1]);
    let m = le(&[0.01, -0.02, 0.03, 0.0, -0.05, 0.5]);
    // A format-3 blob with the format-3 effects (point-mass gravity) reads as the same model.
    let mut old = sample_model(&p, &m);
    old.nominal.effects_mut().list.push(Effect::GravityCompliance { joint: 1, compliance: 1e-3 }).unwrap();
    assert_eq!(decode(&framed(&old, 3)), Ok(old.clone()));
    // Format 4 holds the moments and round-trips them; a format-3 header on the same bytes is refused.
    let model = with_gravity_moment(&p, &m);
    let mut buf = [0u8; 2048];
    let len = encode(&model, &mut buf).unwrap();
    assert_eq!(u16::from_le_bytes([buf[4], buf[5]]), 4);
    assert_eq!(decode(&buf[..len]), Ok(model.clone()));
    assert_eq!(
        decode(&framed(&model, 3)),
        Err(DecodeError::Invalid(ModelError::OutOfRange {
            field: "nominal.effects.list.GravityMoment (not in this blob's format version)"
        }))
    );
}

#[test]
fn an_invalid_gravity_moment_is_named() {
    let bad = |e: Effect| {
        let mut effects = effects_of(&[]);
        effects.list.push(e).unwrap();
        effects.validate(2)
    };
    let at = |field: &'static str| Err(ModelError::OutOfRangeAt { field, index: 0 });
    assert_eq!(
        bad(Effect::GravityMoment { joint: 2, link: 1, mass: 1.0, first_moment: [0.0; 3] }),
        at("nominal.effects.list.GravityMoment.joint")
    );
    assert_eq!(
        bad(Effect::GravityMoment { joint: 0, link: 2, mass: 1.0, first_moment: [0.0; 3] }),
        at("nominal.effects.list.GravityMoment.link")
    );
    assert_eq!(
        bad(Effect::GravityMoment { joint: 1, link: 0, mass: 1.0, first_moment: [0.0; 3] }),
        at("nominal.effects.list.GravityMoment.link (before its joint)")
    );
    assert_eq!(
        bad(Effect::GravityMoment { joint: 0, link: 1, mass: f64::NAN, first_moment: [0.0; 3] }),
        Err(ModelError::NonFinite { field: "nominal.effects.list.GravityMoment.mass", index: 0 })
    );
    assert_eq!(
        bad(Effect::GravityMoment { joint: 0, link: 1, mass: 1.0, first_moment: [0.0, f64::INFINITY, 0.0] }),
        Err(ModelError::NonFinite { field: "nominal.effects.list.GravityMoment.first_moment", index: 0 })
    );
    // Negative products are allowed (c_j may be of either sign; only the product is identified).
    assert_eq!(bad(Effect::GravityMoment { joint: 0, link: 0, mass: -1.0, first_moment: [0.1, 0.0, -0.2] }), Ok(()));
}

/// A chain longer than this build holds is named, with the joint count read from the payload's
/// leading varints (nominal variant, then the planar lengths' count or the DH convention and the
/// joints' count); a count beyond any build, or a payload too short to say, stays `Payload`.
// MAX_JOINTS is the build's (a feature raises it): the range is empty in the default build only.
#[allow(clippy::impossible_comparisons)]
#[test]
fn a_chain_longer_than_the_build_is_named() {
    let expected = |found: usize| {
        if found > MAX_JOINTS && found <= MAX_JOINTS_ANY_BUILD {
            DecodeError::TooManyJoints { found, supported: MAX_JOINTS }
        } else {
            DecodeError::Payload
        }
    };
    for found in [2usize, 7, 8, 10, 16, 17, 300] {
        let count: &[u8] = if found < 128 { &[found as u8] } else { &[0x80 | (found & 0x7f) as u8, (found >> 7) as u8] };
        let dh: std::vec::Vec<u8> = [&[1u8, 0][..], count, &[0xff, 0xff]].concat();
        let planar: std::vec::Vec<u8> = [&[0u8][..], count].concat();
        assert_eq!(payload_error(&dh), expected(found), "DH chain, {found} joints");
        assert_eq!(payload_error(&planar), expected(found), "planar chain, {found} joints");
    }
    assert_eq!(payload_error(&[]), DecodeError::Payload);
    assert_eq!(payload_error(&[1, 0]), DecodeError::Payload);
    assert_eq!(payload_error(&[2, 10]), DecodeError::Payload, "no such nominal variant");
    use std::string::ToString;
    assert!(DecodeError::TooManyJoints { found: 10, supported: 7 }.to_string().contains("long-chains"));
}

/// The varints `payload_error` reads are the ones postcard writes: a real blob's payload gives its
/// own joint count.
#[test]
fn the_joint_count_is_read_where_postcard_writes_it() {
    let (points, momenta) = (le(&[0.0; 18]), le(&[0.0; 9]));
    let planar = sample_model(&points, &momenta);
    let dh = Model { nominal: NominalModel::DhChain(crate::ur5::chain()), ..planar.clone() };
    for (model, leading) in [(planar, [0u8, 2]), (dh, [1u8, 0])] {
        let mut buf = [0u8; 4096];
        let payload = postcard::to_slice(&model, &mut buf).unwrap();
        assert_eq!(payload[..2], leading);
        let count = if leading[0] == 0 { payload[1] } else { payload[2] };
        assert_eq!(usize::from(count), model.n_joints());
    }
}

fn encode_to_vec(model: &Model<'_>) -> Result<Vec<u8>, EncodeError> {
    let mut buf = [0u8; 2048];
    let len = encode(model, &mut buf)?;
    Ok(buf[..len].to_vec())
}

fn with_configuration_kernel<'a>(p: &'a [u8], m: &'a [u8], task_width: Option<f64>) -> Model<'a> {
    let mut model = sample_model(p, m);
    model.integrator = Integrator { method: IntegratorMethod::Euler, steps: 1 };
    model.momentum_law = MomentumLaw::Hamiltonian;
    model.noise_sigma = Some(2e-3);
    model.configuration_kernel = Some(ConfigurationKernel {
        gamma: 0.25,
        axes: heapless::Vec::from_slice(&[JointKernelAxis::Periodic { b: 40.0 }, JointKernelAxis::Periodic { b: 0.5 }]).unwrap(),
        task_width,
    });
    model
}

#[test]
fn format_8_round_trips_the_configuration_kernel_and_older_models_keep_their_format() {
    let p = le(&[0.0, 0.1, 1.0, 1.1, 2.0, 2.1]);
    let m = le(&[0.01, -0.02, 0.03, 0.0, -0.05, 0.5]);
    for width in [None, Some(3.5)] {
        let model = with_configuration_kernel(&p, &m, width);
        assert_eq!(format_for(&model), 8);
        let blob = encode_to_vec(&model).unwrap();
        assert_eq!(u16::from_le_bytes([blob[4], blob[5]]), 8);
        assert_eq!(decode(&blob).unwrap(), model);
    }
    // The same model without the kernel is a format-7 blob, byte for byte the format-8 one's prefix
    // up to σ (the kernel is appended, nothing before it moves).
    let mut plain = with_configuration_kernel(&p, &m, None);
    plain.configuration_kernel = None;
    assert_eq!(format_for(&plain), 7);
    let old = encode_to_vec(&plain).unwrap();
    let new = encode_to_vec(&with_configuration_kernel(&p, &m, None)).unwrap();
    assert_eq!(old[10..old.len() - 4], new[10..old.len() - 4]);
}

#[test]
fn an_invalid_configuration_kernel_is_named() {
    let p = le(&[0.0, 0.1, 1.0, 1.1, 2.0, 2.1]);
    let m = le(&[0.01, -0.02, 0.03, 0.0, -0.05, 0.5]);
    let cases: [(&str, fn(&mut Model<'_>)); 9] = [
        ("configuration_kernel.axes (not the joint kernel's form)", |m| {
            m.configuration_kernel.as_mut().unwrap().axes[0] = JointKernelAxis::Gaussian { width: 1.0 }
        }),
        ("configuration_kernel.gamma", |m| m.configuration_kernel.as_mut().unwrap().gamma = 0.0),
        ("configuration_kernel.gamma", |m| m.configuration_kernel.as_mut().unwrap().gamma = f64::NAN),
        ("configuration_kernel.axes", |m| {
            m.configuration_kernel.as_mut().unwrap().axes.pop();
        }),
        ("configuration_kernel.axes.b", |m| m.configuration_kernel.as_mut().unwrap().axes[1] = JointKernelAxis::Periodic { b: -1.0 }),
        ("configuration_kernel.task_width", |m| m.configuration_kernel.as_mut().unwrap().task_width = Some(f64::INFINITY)),
        ("configuration_kernel (needs the integrator Euler × 1)", |m| m.integrator.steps = 2),
        ("configuration_kernel (needs the integrator Euler × 1)", |m| m.integrator.method = IntegratorMethod::Heun),
        ("configuration_kernel (without noise_sigma)", |m| m.noise_sigma = None),
    ];
    for (field, spoil) in cases {
        let mut model = with_configuration_kernel(&p, &m, Some(1.0));
        spoil(&mut model);
        let err = encode_to_vec(&model).expect_err(field);
        let named = match err {
            EncodeError::Invalid(
                ModelError::NonFinite { field: f, .. }
                | ModelError::OutOfRange { field: f }
                | ModelError::OutOfRangeAt { field: f, .. }
                | ModelError::Dimension { field: f, .. },
            ) => f,
            other => panic!("{field}: {other:?}"),
        };
        assert_eq!(named, field);
    }
}

#[test]
fn format_8_carries_the_drift_beside_sigma_and_refuses_a_bad_one_by_name() {
    let p = le(&[0.0, 0.1, 1.0, 1.1, 2.0, 2.1]);
    let m = le(&[0.01, -0.02, 0.03, 0.0, -0.05, 0.5]);
    let mut model = sample_model(&p, &m);
    model.noise_sigma = Some(0.03);
    model.drift = Some(RowDrift { sd: 0.043, length: 8.4 });
    assert_eq!(format_for(&model), 8);
    let blob = encode_to_vec(&model).unwrap();
    assert_eq!(decode(&blob).unwrap(), model);
    // With the configuration kernel too (Euler × 1): both options round-trip.
    let mut both = with_configuration_kernel(&p, &m, Some(2.0));
    both.drift = Some(RowDrift { sd: 0.0, length: 1.0 });
    assert_eq!(decode(&encode_to_vec(&both).unwrap()).unwrap(), both);
    let cases: [(&str, RowDrift); 4] = [
        ("drift.sd", RowDrift { sd: -1e-3, length: 5.0 }),
        ("drift.sd", RowDrift { sd: f64::NAN, length: 5.0 }),
        ("drift.length", RowDrift { sd: 0.01, length: 0.0 }),
        ("drift.length", RowDrift { sd: 0.01, length: f64::INFINITY }),
    ];
    for (field, drift) in cases {
        let mut bad = model.clone();
        bad.drift = Some(drift);
        let named = match encode_to_vec(&bad).expect_err(field) {
            EncodeError::Invalid(ModelError::NonFinite { field: f, .. } | ModelError::OutOfRange { field: f }) => f,
            other => panic!("{field}: {other:?}"),
        };
        assert_eq!(named, field);
    }
    let mut no_sigma = model.clone();
    no_sigma.noise_sigma = None;
    assert!(matches!(encode_to_vec(&no_sigma), Err(EncodeError::Invalid(ModelError::OutOfRange { field: "drift (without noise_sigma)" }))));
}

#[test]
fn format_9_carries_the_provenance_and_older_models_keep_their_format() {
    let p = le(&[0.0, 0.1, 1.0, 1.1, 2.0, 2.1]);
    let m = le(&[0.01, -0.02, 0.03, 0.0, -0.05, 0.5]);
    let mut model = sample_model(&p, &m);
    model.noise_sigma = Some(0.03);
    model.drift = Some(RowDrift { sd: 0.043, length: 8.4 });
    let format_8 = encode_to_vec(&model).unwrap();
    let frame = ImportFrame { joints: Some(0x0123_4567_89ab_cdef), positions: None };
    let parts = [
        Provenance { import_frame: Some(frame), parent: None },
        Provenance { import_frame: None, parent: Some([7; 32]) },
        Provenance { import_frame: Some(ImportFrame { joints: None, positions: Some(1) }), parent: Some([0xff; 32]) },
    ];
    for provenance in parts {
        let mut with = model.clone();
        with.provenance = Some(provenance);
        assert_eq!(format_for(&with), 9);
        let blob = encode_to_vec(&with).unwrap();
        assert_eq!(decode(&blob).unwrap(), with);
        // The format-8 payload is a prefix of the format-9 one: the provenance is appended.
        assert_eq!(blob[HEADER_LEN..format_8.len() - TRAILER_LEN], format_8[HEADER_LEN..format_8.len() - TRAILER_LEN]);
    }
    // Without a provenance the bytes are the format-8 encoder's.
    assert_eq!(u16::from_le_bytes([format_8[4], format_8[5]]), 8);
    let cases: [(&str, Provenance); 2] = [
        ("provenance (empty: write None)", Provenance { import_frame: None, parent: None }),
        (
            "provenance.import_frame (empty: write None)",
            Provenance { import_frame: Some(ImportFrame { joints: None, positions: None }), parent: None },
        ),
    ];
    for (field, provenance) in cases {
        let mut bad = model.clone();
        bad.provenance = Some(provenance);
        let named = match encode_to_vec(&bad).expect_err(field) {
            EncodeError::Invalid(ModelError::NonFinite { field: f, .. } | ModelError::OutOfRange { field: f }) => f,
            other => panic!("{field}: {other:?}"),
        };
        assert_eq!(named, field);
    }
}

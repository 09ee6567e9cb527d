//! Physical effects (encoder scale, transmission harmonics, gravity compliance, link bending):
//! the runtime's k0_aug against the trainer's independent simulator (`simulate::effects`, its own
//! frame walk and numerical gravity torques) on the RR arm, a 6-joint standard-DH arm (UR5) and a
//! modified-DH chain with a prismatic joint; blobs carrying effects from the trainer through the
//! runtime `Calibrator` (exact Jacobian against finite differences); invalid effects rejected;
//! random effects never panic.

use cbd_protocol::*;
use cbd_runtime::internals::flow::query_derivatives::nominal_hessian;
use cbd_runtime::internals::kinematics::forward_kinematics;
use cbd_runtime::{Calibrator, Error};
use cbd_tests::{lcg, model_blob};
use cbd_trainer::simulate::effects::{EffectArm, InjectedEffect};
use cbd_trainer::simulate::six_joint::{random_configurations, ur5_nominal};
use cbd_trainer::simulate::{configurations, rr, Sampling};

use crate::finite_differences::worst_jacobian_errors;

/// `model` with `list` as its effects.
fn with_effects(model: &NominalModel, list: &[Effect]) -> NominalModel {
    let mut m = model.clone();
    m.effects_mut().list = heapless::Vec::from_slice(list).unwrap();
    m
}

/// One of each effect type on every joint/link, sized for a workspace of reach `reach` and
/// gravity torques up to about `torque`: joint deflections of a few mrad, bending of ~1e-3 reach.
fn every_effect(n: usize, reach: f64, torque: f64) -> Vec<Effect> {
    let mut list = Vec::new();
    for j in 0..n as u8 {
        let f = 1.0 + j as f64;
        list.push(Effect::EncoderScale { joint: j, scale: 1e-3 * f });
        list.push(Effect::Transmission { joint: j, harmonic: 1 + j % 4, cos: 2e-3 / f, sin: -1.5e-3 });
        list.push(Effect::GravityCompliance { joint: j, compliance: 3e-3 / (f * torque) });
        list.push(Effect::LinkBending { link: j, compliance: 1e-3 * reach / f });
        // A link's mass off its end, felt by joint j: c·m and c·m·r with r ~ 0.1–0.3 reach.
        let (link, mass) = ((j + 1).min(n as u8 - 1), 2e-3 / (f * torque));
        list.push(Effect::GravityMoment {
            joint: j,
            link,
            mass,
            first_moment: [0.3 * mass * reach, -0.1 * mass * reach, 0.2 * mass * reach],
        });
    }
    list
}

/// The 6-joint chain of `exact_jacobian.rs` (mm, a prismatic third joint) in the modified convention,
/// with a joint offset on the prismatic joint and a link length on the fifth.
fn modified_chain() -> NominalModel {
    let mut chain = cbd_tests::six_joint_chain(DhConvention::Modified);
    if let NominalModel::DhChain(c) = &mut chain {
        c.joints[2].d = 50.0;
        c.joints[4].a = 30.0;
    }
    chain
}

/// A tilted gravity direction and uneven link masses (one per joint).
fn tilted(model: &mut NominalModel, masses: &[f64]) {
    let (s, c) = (0.3f64.sin(), 0.3f64.cos());
    let norm = (s * s * 0.36 + s * s * 0.64 + c * c).sqrt();
    model.effects_mut().gravity =
        GravityModel { direction: [0.6 * s / norm, 0.8 * s / norm, -c / norm], link_masses: heapless::Vec::from_slice(masses).unwrap() };
}

struct Case {
    name: &'static str,
    rigid: NominalModel,
    configurations: Vec<f64>,
    reach: f64,
    torque: f64,
}

fn cases() -> Vec<Case> {
    let mut ur5_tilted = NominalModel::DhChain(ur5_nominal());
    tilted(&mut ur5_tilted, &[3.7, 8.393, 2.275, 1.219, 1.219, 0.1879]);
    let mut modified = modified_chain();
    tilted(&mut modified, &[2.0, 5.0, 1.0, 1.0, 0.5, 0.2]);
    vec![
        Case {
            name: "rr",
            rigid: rr::nominal(),
            configurations: configurations(Sampling::Uniform { count: 200, seed: 3 }, 2),
            reach: 1.5,
            torque: 3.0,
        },
        Case {
            name: "ur5 (standard DH, mm, unit masses)",
            rigid: NominalModel::DhChain(ur5_nominal()),
            configurations: random_configurations(200, 4),
            reach: 1000.0,
            torque: 3000.0,
        },
        Case {
            name: "ur5 (standard DH, mm, tilted gravity, masses)",
            rigid: ur5_tilted,
            configurations: random_configurations(200, 5),
            reach: 1000.0,
            torque: 10000.0,
        },
        Case {
            name: "modified DH with a prismatic joint (mm)",
            rigid: modified,
            configurations: {
                let mut s = 11u64;
                (0..200 * 6).map(|i| if i % 6 == 2 { 100.0 * lcg(&mut s) } else { 3.0 * lcg(&mut s) }).collect()
            },
            reach: 1000.0,
            torque: 5000.0,
        },
    ]
}

/// Largest |runtime − simulator| over the case's configurations for the effects `list`.
fn runtime_vs_simulator(case: &Case, list: &[Effect]) -> f64 {
    let model = with_effects(&case.rigid, list);
    let mut arm = EffectArm::new(case.rigid.clone());
    arm.effects = list.iter().map(|e| InjectedEffect::from(*e)).collect();
    let n = model.n_joints();
    case.configurations
        .chunks_exact(n)
        .map(|q| {
            let runtime = forward_kinematics(&model, q).position;
            arm.position(q, 0).iter().zip(&runtime).map(|(s, r)| (s - r).abs()).fold(0.0, f64::max)
        })
        .fold(0.0, f64::max)
}

#[test]
fn runtime_matches_the_independent_simulator_for_every_effect_type() {
    for case in cases() {
        let n = case.rigid.n_joints();
        let all = every_effect(n, case.reach, case.torque);
        // Each type alone (one per joint), then everything together.
        let kinds: [(&str, fn(&Effect) -> bool); 5] = [
            ("encoder scale", |e| matches!(e, Effect::EncoderScale { .. })),
            ("transmission", |e| matches!(e, Effect::Transmission { .. })),
            ("gravity compliance", |e| matches!(e, Effect::GravityCompliance { .. })),
            ("link bending", |e| matches!(e, Effect::LinkBending { .. })),
            ("gravity moment", |e| matches!(e, Effect::GravityMoment { .. })),
        ];
        let mut report = Vec::new();
        for (kind, keep) in kinds {
            let list: Vec<Effect> = all.iter().copied().filter(keep).collect();
            let gap = runtime_vs_simulator(&case, &list);
            report.push(format!("{kind} {gap:.1e}"));
            // The effect is really there (moves the tool by ≳ 1e-4 of the reach).
            let rigid_gap = runtime_vs_simulator(&case, &[]);
            assert_eq!(rigid_gap, 0.0, "{}: rigid chains must agree exactly", case.name);
            assert!(gap <= 1e-12 * case.reach, "{} {kind}: runtime vs simulator {gap:e} (reach {})", case.name, case.reach);
        }
        let gap = runtime_vs_simulator(&case, &all);
        let moved = {
            let model = with_effects(&case.rigid, &all);
            case.configurations
                .chunks_exact(n)
                .map(|q| {
                    let (a, b) = (forward_kinematics(&model, q).position, forward_kinematics(&case.rigid, q).position);
                    a.iter().zip(&b).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max)
                })
                .fold(0.0, f64::max)
        };
        assert!(moved > 1e-3 * case.reach, "{}: the effects move the tool by only {moved:e}", case.name);
        assert!(gap <= 1e-12 * case.reach, "{} all effects: runtime vs simulator {gap:e}", case.name);
        eprintln!(
            "{}: runtime vs simulator, max |difference| (reach {}): {}, all {} together {gap:.1e} (they move the tool by up to {moved:.2e})",
            case.name,
            case.reach,
            report.join(", "),
            all.len()
        );
    }
}

#[test]
fn gravity_torques_match_the_simulators_numerical_torques() {
    // The simulator differentiates V numerically (central differences, step 1e-6): its torques
    // carry a rounding error of about ε·|V|/1e-6, which is what limits the agreement of the
    // gravity-compliance positions above.
    for case in cases() {
        let n = case.rigid.n_joints();
        let (mut worst, mut largest): (f64, f64) = (0.0, 0.0);
        for q in case.configurations.chunks_exact(n) {
            let runtime = cbd_runtime::internals::kinematics::augmented::gravity_torques(&case.rigid, q);
            let sim = cbd_trainer::simulate::effects::gravity_torques_numerical(&case.rigid, &case.rigid.effects().gravity, q);
            for (a, b) in runtime.iter().zip(&sim) {
                worst = worst.max((a - b).abs());
                largest = largest.max(b.abs());
            }
        }
        eprintln!(
            "{}: gravity torques, runtime (closed form) vs simulator (numerical): {worst:.1e} (largest |τ| {largest:.1e})",
            case.name
        );
        assert!(worst <= 1e-8 * largest, "{}: {worst:e}", case.name);
    }
}

#[test]
fn augmented_jacobian_and_hessian_match_finite_differences_on_the_test_arms() {
    for case in cases() {
        let n = case.rigid.n_joints();
        let m = case.rigid.task_dim();
        let model = with_effects(&case.rigid, &every_effect(n, case.reach, case.torque));
        let (mut worst_j, mut worst_h): (f64, f64) = (0.0, 0.0);
        for q in case.configurations.chunks_exact(n).take(20) {
            let k = forward_kinematics(&model, q);
            let h = nominal_hessian(&model, q);
            let scale = k.jacobian.iter().flatten().fold(0.0f64, |a, v| a.max(v.abs()));
            let step = 1e-6;
            for d in 0..n {
                let (mut qa, mut qb) = (q.to_vec(), q.to_vec());
                qa[d] += step;
                qb[d] -= step;
                let (ka, kb) = (forward_kinematics(&model, &qa), forward_kinematics(&model, &qb));
                for a in 0..m {
                    let fd = (ka.position[a] - kb.position[a]) / (2.0 * step);
                    worst_j = worst_j.max((fd - k.jacobian[a][d]).abs() / scale);
                    for e in 0..n {
                        let fd = (ka.jacobian[a][e] - kb.jacobian[a][e]) / (2.0 * step);
                        worst_h = worst_h.max((fd - h[a][e][d]).abs() / scale);
                    }
                }
            }
        }
        eprintln!("{}: Dk0_aug vs central differences {worst_j:.1e}, D²k0_aug {worst_h:.1e} (relative to max |Dk0_aug|)", case.name);
        assert!(worst_j < 1e-7 && worst_h < 1e-6, "{}: Jacobian {worst_j:e}, Hessian {worst_h:e}", case.name);
    }
}

#[test]
fn trainer_blob_with_effects_round_trips_and_its_exact_jacobian_matches_finite_differences() {
    // The "real" RR arm: longer links plus every effect; the nominal model declares the effects
    // (as `cbd diagnose` would) and CbD fits what is left.
    let effects = [
        Effect::EncoderScale { joint: 0, scale: 2e-3 },
        Effect::Transmission { joint: 1, harmonic: 2, cos: 2e-3, sin: -1e-3 },
        Effect::GravityCompliance { joint: 1, compliance: 4e-3 },
        Effect::LinkBending { link: 0, compliance: 5e-3 },
        Effect::LinkBending { link: 1, compliance: 3e-3 },
    ];
    let mut real = EffectArm::new(NominalModel::planar(&[1.02, 0.48]).unwrap());
    real.effects = effects.iter().map(|e| InjectedEffect::from(*e)).collect();
    let train = real.measure(&configurations(Sampling::Grid { per_axis: 8 }, 2), 0.0, 1);
    let nominal = with_effects(&rr::nominal(), &effects);
    let mut opts = cbd_trainer::solver::CbdOptions::paper_rr();
    opts.solver.max_iterations = 8;
    let fit = cbd_trainer::solver::fit_cbd(&nominal, &train, &opts).expect("fit");
    let mut storage = vec![0.0; 100_000];
    let mut cal = Calibrator::load(&fit.blob, &mut storage).expect("load");
    assert_eq!(cal.model().nominal, nominal, "the blob carries the effects");
    // The runtime reproduces the trainer at the training points.
    let mut worst: f64 = 0.0;
    for i in 0..train.len() {
        let e = cal.evaluate(train.joints(i)).unwrap();
        for (a, b) in e.position().iter().zip(&fit.train_predictions[2 * i..2 * i + 2]) {
            worst = worst.max((a - b).abs());
        }
    }
    assert!(worst <= 1e-12, "runtime vs trainer at the training points: {worst:e}");
    let mut s = 5u64;
    let queries: Vec<Vec<f64>> = (0..10).map(|_| (0..2).map(|_| 3.0 * lcg(&mut s)).collect()).collect();
    let exact = worst_jacobian_errors(&mut cal, &queries, 1e-6).0;
    // The calibrated model sees the effects: its training error is far below the rigid model's.
    let rigid_error = (0..train.len())
        .map(|i| {
            let p = forward_kinematics(&rr::nominal(), train.joints(i)).position;
            (p[0] - train.position(i)[0]).hypot(p[1] - train.position(i)[1])
        })
        .fold(0.0, f64::max);
    let calibrated_error = (0..train.len())
        .map(|i| (fit.train_predictions[2 * i] - train.position(i)[0]).hypot(fit.train_predictions[2 * i + 1] - train.position(i)[1]))
        .fold(0.0, f64::max);
    eprintln!(
        "RR blob with effects: runtime vs trainer {worst:.1e}; exact Jacobian vs finite differences {exact:.1e}; \
         training error max {calibrated_error:.2e} (nominal without effects {rigid_error:.2e})"
    );
    assert!(exact < 1e-7, "exact Jacobian off by {exact:e}");
    assert!(calibrated_error < 0.1 * rigid_error);
}

#[test]
fn six_joint_blobs_with_effects_have_exact_jacobians() {
    for case in cases().into_iter().skip(1) {
        let n = case.rigid.n_joints();
        let nominal = with_effects(&case.rigid, &every_effect(n, case.reach, case.torque));
        for integrator in [Integrator { method: IntegratorMethod::Euler, steps: 2 }, Integrator { method: IntegratorMethod::Rk4, steps: 3 }]
        {
            let blob = model_blob(nominal.clone(), 30, 0.02, integrator, 100.0);
            let mut storage = vec![0.0; 200_000];
            let mut cal = Calibrator::load(&blob, &mut storage).unwrap();
            assert_eq!(cal.model().nominal.effects().list.len(), 5 * n);
            let queries: Vec<Vec<f64>> = case.configurations.chunks_exact(n).take(5).map(|q| q.to_vec()).collect();
            let exact = worst_jacobian_errors(&mut cal, &queries, 1e-6).0;
            eprintln!("{} {integrator:?}: exact Jacobian vs finite differences {exact:.1e}", case.name);
            assert!(exact < 1e-7, "{}: exact Jacobian off by {exact:e}", case.name);
        }
    }
}

/// Frames `model` by hand (without `encode`'s validation).
fn framed_without_validation(model: &Model<'_>) -> Vec<u8> {
    let payload = postcard::to_allocvec(model).unwrap();
    let mut blob = Vec::new();
    blob.extend_from_slice(&MAGIC);
    // Format 4: the payload is the model alone (no expansion follows).
    blob.extend_from_slice(&FORMAT_WITHOUT_EXPANSION.to_le_bytes());
    blob.extend_from_slice(&(payload.len() as u32).to_le_bytes());
    blob.extend_from_slice(&payload);
    let crc = crc32(&blob);
    blob.extend_from_slice(&crc.to_le_bytes());
    blob
}

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

#[test]
fn blobs_with_out_of_range_effects_are_rejected() {
    let nominal = with_effects(&NominalModel::DhChain(ur5_nominal()), &[Effect::GravityCompliance { joint: 6, compliance: 1e-7 }]);
    let points = f64_le_bytes(&[0.0; 6]);
    let momenta = f64_le_bytes(&[0.0; 3]);
    let model = Model {
        nominal,
        normalisation: Normalisation::IDENTITY,
        joint_kernel: JointKernel { gamma: 1.0, axes: heapless::Vec::from_slice(&[JointKernelAxis::Periodic { b: 1.0 }; 6]).unwrap() },
        task_kernel: TaskKernel { width: 1.0 },
        integrator: Integrator { method: IntegratorMethod::Euler, steps: 1 },
        momentum_law: MomentumLaw::WithDivergence,
        sigma: 1.0,
        n_points: 1,
        points: F64Slice::from_le_bytes(&points),
        momenta: F64Slice::from_le_bytes(&momenta),
        expansion: None,
        noise_sigma: None,
        configuration_kernel: None,
        drift: None,
        provenance: None,
    };
    let expected = ModelError::OutOfRangeAt { field: "nominal.effects.list.GravityCompliance.joint", index: 0 };
    assert_eq!(encode_to_vec(&model), Err(EncodeError::Invalid(expected)));
    let blob = framed_without_validation(&model);
    let mut storage = vec![0.0; 10_000];
    assert_eq!(Calibrator::load(&blob, &mut storage).err(), Some(Error::Blob(DecodeError::Invalid(expected))));
    // The same blob with the joint in range loads.
    let mut fixed = model.clone();
    fixed.nominal.effects_mut().list[0] = Effect::GravityCompliance { joint: 5, compliance: 1e-7 };
    assert!(Calibrator::load(&encode_to_vec(&fixed).unwrap(), &mut storage).is_ok());
}

#[test]
fn random_effects_never_panic_in_the_calibrator() {
    let mut s = 99u64;
    let mut outcomes = [0usize; 3];
    for round in 0..300 {
        let base = match round % 3 {
            0 => rr::nominal(),
            1 => NominalModel::DhChain(ur5_nominal()),
            _ => modified_chain(),
        };
        let n = base.n_joints();
        let mut list = Vec::new();
        for _ in 0..(lcg(&mut s).abs() * 10.0) as usize {
            // Mostly valid indices and harmonics, sometimes out of range; values of any size.
            let index = ((lcg(&mut s).abs() * (n as f64 + 1.5)) as u8).min(255);
            let value = lcg(&mut s) * 10f64.powf(6.0 * lcg(&mut s));
            let harmonic = (lcg(&mut s).abs() * 18.0) as u8;
            list.push(match (lcg(&mut s).abs() * 5.0) as usize {
                0 => Effect::EncoderScale { joint: index, scale: value },
                1 => Effect::Transmission { joint: index, harmonic, cos: value, sin: -value },
                2 => Effect::GravityCompliance { joint: index, compliance: value },
                3 => Effect::LinkBending { link: index, compliance: value },
                _ => Effect::GravityMoment { joint: index, link: harmonic % 8, mass: value, first_moment: [-value, 0.5 * value, value] },
            });
        }
        let nominal = with_effects(&base, &list);
        let valid = nominal.effects().validate(n).is_ok();
        let axes: heapless::Vec<JointKernelAxis, { cbd_protocol::MAX_JOINTS }> = (0..n)
            .map(|d| if nominal.is_revolute(d) { JointKernelAxis::Periodic { b: 1.0 } } else { JointKernelAxis::Gaussian { width: 100.0 } })
            .collect();
        let points: Vec<f64> = (0..4 * n).map(|_| 3.0 * lcg(&mut s)).collect();
        let momenta: Vec<f64> = (0..4 * nominal.task_dim()).map(|_| 0.01 * lcg(&mut s)).collect();
        let (pb, mb) = (f64_le_bytes(&points), f64_le_bytes(&momenta));
        let model = Model {
            nominal,
            normalisation: Normalisation::IDENTITY,
            joint_kernel: JointKernel { gamma: 1.0, axes },
            task_kernel: TaskKernel { width: 1000.0 },
            integrator: Integrator { method: IntegratorMethod::Heun, steps: 2 },
            momentum_law: MomentumLaw::WithDivergence,
            sigma: 1.0,
            n_points: 4,
            points: F64Slice::from_le_bytes(&pb),
            momenta: F64Slice::from_le_bytes(&mb),
            expansion: None,
            noise_sigma: None,
            configuration_kernel: None,
            drift: None,
            provenance: None,
        };
        let mut storage = vec![0.0; 20_000];
        match encode_to_vec(&model) {
            Err(EncodeError::Invalid(_)) => {
                assert!(!valid);
                assert!(Calibrator::from_model(model, &mut storage).is_err());
                outcomes[0] += 1;
            }
            Err(e) => panic!("{e:?}"),
            Ok(blob) => {
                assert!(valid);
                let mut cal = match Calibrator::load(&blob, &mut storage) {
                    Ok(cal) => cal,
                    Err(Error::Diverged) => continue,
                    Err(e) => panic!("{e:?}"),
                };
                for _ in 0..3 {
                    let q: Vec<f64> = (0..n).map(|_| 4.0 * lcg(&mut s)).collect();
                    match cal.evaluate(&q) {
                        Ok(e) => {
                            assert!(e.position().iter().chain(e.jacobian().iter()).all(|v| v.is_finite()));
                            outcomes[1] += 1;
                        }
                        Err(Error::NonFiniteResult) => outcomes[2] += 1,
                        Err(e) => panic!("{e:?}"),
                    }
                }
            }
        }
    }
    eprintln!("random effects: {} rejected models, {} evaluations, {} non-finite results", outcomes[0], outcomes[1], outcomes[2]);
    assert!(outcomes[0] > 10 && outcomes[1] > 100);
}

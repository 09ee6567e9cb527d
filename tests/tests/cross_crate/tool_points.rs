//! Several tool points per pose (issue 26 item 1): every tool point is carried by the same flows,
//! control point c is tool point c % m_p, and `evaluate_point` is exact.

use cbd_protocol::*;
use cbd_runtime::internals::flow::control_points::{initial_state, integrate_control_points};
use cbd_runtime::internals::flow::{Dims, FlowParams};
use cbd_runtime::{Calibrator, Error};
use cbd_tests::lcg;

/// Three tool points 100 mm apart in a tilted tool frame.
pub const THREE: [[f64; 3]; 3] = [[0.0, 0.0, 0.0], [100.0, 0.0, 0.0], [0.0, 100.0, 0.0]];

/// The UR5 (mm) with a rotated tool frame and `tool_points`.
fn ur5_with(tool_points: &[[f64; 3]]) -> NominalModel {
    let mut c = ur5::chain();
    let (s, co) = (0.4f64.sin(), 0.4f64.cos());
    c.tool.rotation = [co, -s, 0.0, s * 0.6, co * 0.6, -0.8, s * 0.8, co * 0.8, 0.6];
    c.tool.translation = [3.0, -2.0, 31.0];
    c.tool_points = heapless::Vec::from_slice(tool_points).unwrap();
    NominalModel::DhChain(c)
}

/// `poses` pseudo-random configurations, each repeated for every tool point, and random momenta.
fn arrays(poses: usize, m_p: usize, momentum: f64) -> (Vec<f64>, Vec<f64>) {
    let mut s = 11u64;
    let mut points = Vec::new();
    for _ in 0..poses {
        let q: Vec<f64> = (0..6).map(|_| 3.0 * lcg(&mut s)).collect();
        for _ in 0..m_p {
            points.extend_from_slice(&q);
        }
    }
    let momenta = (0..poses * m_p * 3).map(|_| momentum * lcg(&mut s)).collect();
    (points, momenta)
}

fn model<'a>(nominal: NominalModel, points: &'a [u8], momenta: &'a [u8], integrator: Integrator) -> Model<'a> {
    Model {
        n_points: (points.len() / 48) as u32,
        nominal,
        normalisation: Normalisation { task_offset: [0.0, 0.0, 300.0], task_scale: 500.0 },
        joint_kernel: JointKernel { gamma: 2.0, axes: heapless::Vec::from_slice(&[JointKernelAxis::Periodic { b: 1.0 }; 6]).unwrap() },
        task_kernel: TaskKernel { width: 0.8 },
        integrator,
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

const RK4: Integrator = Integrator { method: IntegratorMethod::Rk4, steps: 3 };

#[test]
fn each_control_point_is_its_tool_point_and_a_query_there_follows_it() {
    let (x, p) = arrays(12, 3, 0.02);
    let (xb, pb) = (f64_le_bytes(&x), f64_le_bytes(&p));
    let model = model(ur5_with(&THREE), &xb, &pb, RK4);
    let dims = Dims { n: 6, m: 3 };
    let mut state = vec![0.0; 36 * dims.state_len()];
    initial_state(&model, &mut state).unwrap();
    // k(0) of control point c is k0 of tool point c % 3, normalised.
    for (c, s) in state.chunks(dims.state_len()).enumerate() {
        let k0 = cbd_runtime::internals::kinematics::forward_kinematics_at(&model.nominal, &x[6 * c..6 * c + 6], c % 3)
            .normalised(&model.normalisation);
        assert_eq!(&s[..3], &k0.position[..], "control point {c}");
    }
    let flow_kernel = model.joint_kernel.for_flow(model.momentum_law);
    let params = FlowParams { dims, joint_kernel: &flow_kernel, task_kernel: &model.task_kernel, law: model.momentum_law };
    let mut scratch = vec![0.0; 3 * state.len()];
    let mut traj = vec![0.0; model.integrator.stage_count() * 36 * dims.sample_len()];
    integrate_control_points(&params, model.integrator, &x, &mut state, &mut scratch, &mut traj, |_, _| {}).unwrap();
    // A query at a control point's configuration, from the same tool point, integrates the same
    // k and J equations with the same fields: it ends where the control point ends.
    let blob = encode_to_vec(&model).unwrap();
    assert_eq!(u16::from_le_bytes([blob[4], blob[5]]), 6);
    let mut storage = vec![0.0; cbd_runtime::storage_len_for(&model)];
    let mut cal = Calibrator::load(&blob, &mut storage).unwrap();
    let mut worst: f64 = 0.0;
    for (c, s) in state.chunks(dims.state_len()).enumerate() {
        let e = cal.evaluate_point(&x[6 * c..6 * c + 6], c % 3).unwrap();
        for a in 0..3 {
            let reference = model.normalisation.position_to_user(a, s[a]);
            worst = worst.max((e.position()[a] - reference).abs());
        }
    }
    eprintln!("query at the control points vs their own flow: worst {worst:.2e} mm");
    assert!(worst < 1e-9, "worst {worst:e} mm");
}

#[test]
fn evaluate_point_has_the_exact_jacobian_and_point_zero_is_evaluate() {
    let (x, p) = arrays(10, 3, 0.02);
    let (xb, pb) = (f64_le_bytes(&x), f64_le_bytes(&p));
    for integrator in [Integrator { method: IntegratorMethod::Euler, steps: 2 }, RK4] {
        let blob = encode_to_vec(&model(ur5_with(&THREE), &xb, &pb, integrator)).unwrap();
        let mut storage = vec![0.0; 200_000];
        let mut cal = Calibrator::load(&blob, &mut storage).unwrap();
        let mut s = 5u64;
        let mut worst: f64 = 0.0;
        for _ in 0..4 {
            let q: Vec<f64> = (0..6).map(|_| 3.0 * lcg(&mut s)).collect();
            assert_eq!(cal.evaluate_point(&q, 0).unwrap(), cal.evaluate(&q).unwrap());
            for j in 0..3 {
                let e = cal.evaluate_point(&q, j).unwrap();
                let scale = e.jacobian().iter().fold(0.0f64, |m, v| m.max(v.abs()));
                let h = 1e-6;
                for d in 0..6 {
                    let (mut qa, mut qb) = (q.clone(), q.clone());
                    qa[d] += h;
                    qb[d] -= h;
                    let (ya, yb) = (cal.evaluate_point(&qa, j).unwrap(), cal.evaluate_point(&qb, j).unwrap());
                    for a in 0..3 {
                        let fd = (ya.position()[a] - yb.position()[a]) / (2.0 * h);
                        worst = worst.max((fd - e.jacobian()[(a, d)]).abs() / scale);
                    }
                }
            }
            assert_eq!(cal.evaluate_point(&q, 3), Err(Error::ToolPoint { index: 3, count: 3 }));
        }
        eprintln!("{integrator:?}: evaluate_point's Jacobian vs central differences, worst {worst:.1e} (relative to max |Dk1|)");
        assert!(worst < 1e-7, "{worst:e}");
    }
}

#[test]
fn one_tool_point_at_the_origin_evaluates_as_a_model_without_tool_points() {
    let (x, p) = arrays(10, 1, 0.02);
    let (xb, pb) = (f64_le_bytes(&x), f64_le_bytes(&p));
    let plain = encode_to_vec(&model(ur5_with(&[]), &xb, &pb, RK4)).unwrap();
    let origin = encode_to_vec(&model(ur5_with(&[[0.0; 3]]), &xb, &pb, RK4)).unwrap();
    assert_eq!((u16::from_le_bytes([plain[4], plain[5]]), u16::from_le_bytes([origin[4], origin[5]])), (4, 6));
    let (mut s1, mut s2) = (vec![0.0; 200_000], vec![0.0; 200_000]);
    let (mut a, mut b) = (Calibrator::load(&plain, &mut s1).unwrap(), Calibrator::load(&origin, &mut s2).unwrap());
    let mut s = 9u64;
    for _ in 0..5 {
        let q: Vec<f64> = (0..6).map(|_| 3.0 * lcg(&mut s)).collect();
        assert_eq!(a.evaluate(&q).unwrap(), b.evaluate(&q).unwrap());
        assert_eq!(a.evaluate_point(&q, 1), Err(Error::ToolPoint { index: 1, count: 1 }));
    }
}

#[test]
fn without_a_deformation_the_pose_is_the_nominal_tool_frame() {
    let (x, _) = arrays(8, 3, 0.0);
    let zeros = vec![0.0; 8 * 3 * 3];
    let (xb, pb) = (f64_le_bytes(&x), f64_le_bytes(&zeros));
    let nominal = ur5_with(&THREE);
    let blob = encode_to_vec(&model(nominal.clone(), &xb, &pb, RK4)).unwrap();
    let mut storage = vec![0.0; 200_000];
    let mut cal = Calibrator::load(&blob, &mut storage).unwrap();
    let NominalModel::DhChain(chain) = &nominal else { unreachable!() };
    let q = [0.3, -1.1, 1.4, 0.2, -0.7, 2.1];
    let pose = cal.evaluate_pose(&q).unwrap();
    let walk = cbd_runtime::internals::kinematics::rigid::dh_walk(chain, &q);
    for a in 0..3 {
        assert!((pose.origin()[a] - walk.tool[a]).abs() < 1e-9, "origin");
        for b in 0..3 {
            assert!((pose.rotation()[a][b] - walk.tool_rotation[a][b]).abs() < 1e-12, "rotation");
        }
    }
    assert!(pose.fit_residual() < 1e-9);
    // The nominal geometric Jacobian: z_i × (t − o_i) and z_i for revolute joints.
    for d in 0..6 {
        let lin =
            cross3(walk.axes[d], [walk.tool[0] - walk.origins[d][0], walk.tool[1] - walk.origins[d][1], walk.tool[2] - walk.origins[d][2]]);
        for a in 0..3 {
            assert!((pose.jacobian()[(a, d)] - lin[a]).abs() < 1e-8, "linear [{a}][{d}]");
            assert!((pose.jacobian()[(3 + a, d)] - walk.axes[d][a]).abs() < 1e-10, "angular [{a}][{d}]");
        }
    }
}

fn cross3(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}

/// The rotation vector of R_a R_bᵀ (small angles: vee of the skew part).
fn small_rotation(a: [[f64; 3]; 3], b: [[f64; 3]; 3]) -> [f64; 3] {
    let m = |i: usize, j: usize| (0..3).map(|k| a[i][k] * b[j][k]).sum::<f64>();
    [0.5 * (m(2, 1) - m(1, 2)), 0.5 * (m(0, 2) - m(2, 0)), 0.5 * (m(1, 0) - m(0, 1))]
}

#[test]
fn the_pose_jacobian_matches_finite_differences() {
    let (x, p) = arrays(10, 3, 0.05);
    let (xb, pb) = (f64_le_bytes(&x), f64_le_bytes(&p));
    for integrator in [Integrator { method: IntegratorMethod::Euler, steps: 1 }, RK4] {
        let blob = encode_to_vec(&model(ur5_with(&THREE), &xb, &pb, integrator)).unwrap();
        let mut storage = vec![0.0; 200_000];
        let mut cal = Calibrator::load(&blob, &mut storage).unwrap();
        let mut s = 21u64;
        let (mut worst_lin, mut worst_ang, mut residual): (f64, f64, f64) = (0.0, 0.0, 0.0);
        for _ in 0..4 {
            let q: Vec<f64> = (0..6).map(|_| 3.0 * lcg(&mut s)).collect();
            let pose = cal.evaluate_pose(&q).unwrap();
            residual = residual.max(pose.fit_residual());
            for j in 0..3 {
                assert_eq!(pose.point(j).unwrap(), &cal.evaluate_point(&q, j).unwrap());
            }
            let scale_lin = (0..6).flat_map(|d| (0..3).map(move |a| (a, d))).fold(0.0f64, |m, (a, d)| m.max(pose.jacobian()[(a, d)].abs()));
            let scale_ang = (0..6).flat_map(|d| (3..6).map(move |a| (a, d))).fold(0.0f64, |m, (a, d)| m.max(pose.jacobian()[(a, d)].abs()));
            let h = 1e-6;
            for d in 0..6 {
                let (mut qa, mut qb) = (q.clone(), q.clone());
                qa[d] += h;
                qb[d] -= h;
                let (pa, pb) = (cal.evaluate_pose(&qa).unwrap(), cal.evaluate_pose(&qb).unwrap());
                let omega = small_rotation(pa.rotation(), pb.rotation());
                for a in 0..3 {
                    let fd = (pa.origin()[a] - pb.origin()[a]) / (2.0 * h);
                    worst_lin = worst_lin.max((fd - pose.jacobian()[(a, d)]).abs() / scale_lin);
                    worst_ang = worst_ang.max((omega[a] / (2.0 * h) - pose.jacobian()[(3 + a, d)]).abs() / scale_ang);
                }
            }
        }
        eprintln!(
            "{integrator:?}: pose Jacobian vs central differences, worst linear {worst_lin:.1e}, angular {worst_ang:.1e} (relative); fit residual up to {residual:.2e} mm"
        );
        assert!(worst_lin < 1e-7 && worst_ang < 1e-7, "{worst_lin:e} {worst_ang:e}");
    }
}

#[test]
fn two_or_collinear_tool_points_leave_the_orientation_undetermined() {
    for points in [&[[0.0, 0.0, 0.0], [100.0, 0.0, 0.0]][..], &[[0.0; 3], [100.0, 0.0, 0.0], [200.0, 0.0, 0.0]][..], &[][..]] {
        let m_p = points.len().max(1);
        let (x, p) = arrays(6, m_p, 0.02);
        let (xb, pb) = (f64_le_bytes(&x), f64_le_bytes(&p));
        let blob = encode_to_vec(&model(ur5_with(points), &xb, &pb, RK4)).unwrap();
        let mut storage = vec![0.0; 200_000];
        let mut cal = Calibrator::load(&blob, &mut storage).unwrap();
        let q = [0.3, -1.1, 1.4, 0.2, -0.7, 2.1];
        assert_eq!(cal.evaluate_pose(&q), Err(Error::OrientationUndetermined), "{points:?}");
        assert!(cal.evaluate_point(&q, m_p - 1).is_ok());
    }
}

/// Pose compensation on reachable targets (the calibrated pose at a known configuration), from a
/// seed 0.2 rad off per joint: counts of reached targets, worst residuals.
fn pose_compensation_on(nominal: NominalModel, momentum: f64, label: &str) -> (usize, usize) {
    let (x, p) = arrays(40, 3, momentum);
    let (xb, pb) = (f64_le_bytes(&x), f64_le_bytes(&p));
    let blob = encode_to_vec(&model(nominal, &xb, &pb, RK4)).unwrap();
    let mut storage = vec![0.0; 200_000];
    let mut cal = Calibrator::load(&blob, &mut storage).unwrap();
    let options = cbd_runtime::PoseCompensateOptions::for_model(&cal);
    let mut s = 77u64;
    let (mut reached, total) = (0, 200);
    let (mut worst_p, mut worst_a, mut worst_start_p, mut deformation): (f64, f64, f64, f64) = (0.0, 0.0, 0.0, 0.0);
    for _ in 0..total {
        // Away from the wrist singularity (|sin q5| > 0.3) so that the target is regular.
        let mut q: Vec<f64> = (0..6).map(|_| 2.5 * lcg(&mut s)).collect();
        if q[4].sin().abs() < 0.3 {
            q[4] = 1.2;
        }
        let pose = cal.evaluate_pose(&q).unwrap();
        let (nominal_frame, _) = cbd_runtime::internals::kinematics::tool_point::nominal_tool_frame(&cal.model().nominal, &q).unwrap();
        let shift: f64 = (0..3).map(|a| (pose.origin()[a] - nominal_frame.origin[a]).powi(2)).sum::<f64>().sqrt();
        deformation = deformation.max(shift);
        let seed: Vec<f64> = q.iter().map(|v| v + 0.2 * lcg(&mut s)).collect();
        let mut out = [0.0; 6];
        let c = cal.compensate_pose(&pose.origin(), &pose.rotation(), &seed, &mut out).unwrap();
        // The start alone: no Gauss–Newton step.
        let start = cal
            .compensate_pose_with(
                &pose.origin(),
                &pose.rotation(),
                &seed,
                &mut [0.0; 6],
                &cbd_runtime::PoseCompensateOptions { iterations: 0, ..options },
            )
            .unwrap();
        worst_start_p = worst_start_p.max(start.position_residual);
        // The command's pose, re-evaluated, is what the residuals report.
        let back = cal.evaluate_pose(&out).unwrap();
        let miss: f64 = (0..3).map(|a| (back.origin()[a] - pose.origin()[a]).powi(2)).sum::<f64>().sqrt();
        assert!((miss - c.position_residual).abs() <= 1e-12 * (1.0 + miss), "{miss} vs {}", c.position_residual);
        if c.reached {
            reached += 1;
        } else {
            eprintln!(
                "  unreached: q {q:.3?} start {:.2e} mm, final {:.2e} mm {:.2e} rad, conditioning {:.1e}",
                start.position_residual, c.position_residual, c.angle_residual, c.conditioning
            );
            worst_p = worst_p.max(c.position_residual);
            worst_a = worst_a.max(c.angle_residual);
        }
    }
    eprintln!(
        "{label}: pose compensation reached {reached}/{total} (tolerances {:.1e} mm, {:.1e} rad); unreached worst {worst_p:.2e} mm, {worst_a:.2e} rad; the start alone within {worst_start_p:.2e} mm; k1 − k0 at the origin up to {deformation:.2} mm",
        options.position_tolerance, options.angle_tolerance
    );
    (reached, total)
}

#[test]
fn pose_compensation_reaches_reachable_poses() {
    // UR-type (closed-form start) and with a bending effect (no closed form: Gauss–Newton on k0).
    let (r, t) = pose_compensation_on(ur5_with(&THREE), 0.02, "UR5, three tool points");
    assert!(r * 100 >= 98 * t, "{r}/{t}");
    let NominalModel::DhChain(mut c) = ur5_with(&THREE) else { unreachable!() };
    c.effects.list.push(Effect::LinkBending { link: 2, compliance: 2e-6 }).unwrap();
    let (r, t) = pose_compensation_on(NominalModel::DhChain(c), 0.02, "UR5 with link bending (no closed form)");
    assert!(r * 100 >= 95 * t, "{r}/{t}");
}

#[test]
fn pose_compensation_refuses_what_it_cannot_do() {
    let (x, p) = arrays(6, 3, 0.02);
    let (xb, pb) = (f64_le_bytes(&x), f64_le_bytes(&p));
    let blob = encode_to_vec(&model(ur5_with(&THREE), &xb, &pb, RK4)).unwrap();
    let mut storage = vec![0.0; 200_000];
    let mut cal = Calibrator::load(&blob, &mut storage).unwrap();
    let id = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    let mut out = [0.0; 6];
    let seed = [0.0; 6];
    let mirror = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, -1.0]];
    assert_eq!(cal.compensate_pose(&[100.0, 0.0, 300.0], &mirror, &seed, &mut out), Err(Error::InvalidRotation));
    assert_eq!(cal.compensate_pose(&[100.0, f64::NAN, 300.0], &id, &seed, &mut out), Err(Error::NonFiniteTarget { index: 1 }));
    assert_eq!(cal.compensate_pose(&[100.0, 0.0, 300.0], &id, &seed[..5], &mut out), Err(Error::QueryDimension { expected: 6, found: 5 }));
    // One tool point: no orientation.
    let (x1, p1) = arrays(6, 1, 0.02);
    let (xb1, pb1) = (f64_le_bytes(&x1), f64_le_bytes(&p1));
    let blob = encode_to_vec(&model(ur5_with(&[]), &xb1, &pb1, RK4)).unwrap();
    let mut storage = vec![0.0; 200_000];
    let mut cal = Calibrator::load(&blob, &mut storage).unwrap();
    assert_eq!(cal.compensate_pose(&[100.0, 0.0, 300.0], &id, &seed, &mut out), Err(Error::OrientationUndetermined));
    // A planar arm has too few joints.
    let blob = cbd_tests::reference_blob();
    let mut storage = vec![0.0; 200_000];
    let mut cal = Calibrator::load(&blob, &mut storage).unwrap();
    let mut out2 = [0.0; 2];
    assert_eq!(cal.compensate_pose(&[1.0, 0.0, 0.0], &id, &[0.0; 2], &mut out2), Err(Error::TooFewJoints { found: 2, needed: 6 }));
}

#[test]
fn position_compensation_targets_tool_point_zero() {
    // Tool point 0 off the tool frame's origin: the inverse-flow start inverts k0 of that point.
    let points = [[30.0, 20.0, 10.0], [100.0, 0.0, 0.0], [0.0, 100.0, 0.0]];
    let (x, p) = arrays(40, 3, 0.02);
    let (xb, pb) = (f64_le_bytes(&x), f64_le_bytes(&p));
    let blob = encode_to_vec(&model(ur5_with(&points), &xb, &pb, RK4)).unwrap();
    let mut storage = vec![0.0; 200_000];
    let mut cal = Calibrator::load(&blob, &mut storage).unwrap();
    let mut s = 99u64;
    let (mut reached, mut worst_start): (usize, f64) = (0, 0.0);
    for _ in 0..100 {
        let q: Vec<f64> = (0..6).map(|_| 2.5 * lcg(&mut s)).collect();
        let target: Vec<f64> = cal.evaluate(&q).unwrap().position().iter().copied().collect();
        let mut start = [0.0; 6];
        cal.inverse_flow_start(&target, &q, &mut start, 8).unwrap();
        let y: Vec<f64> = cal.evaluate(&start).unwrap().position().iter().copied().collect();
        worst_start = worst_start.max((0..3).map(|a| (y[a] - target[a]).powi(2)).sum::<f64>().sqrt());
        let mut out = [0.0; 6];
        reached += usize::from(cal.compensate(&target, &q, &mut out).unwrap().reached);
    }
    eprintln!("position compensation of tool point 0 (off the origin): reached {reached}/100, the start within {worst_start:.2e} mm");
    assert!(reached >= 98 && worst_start < 5.0, "{reached} {worst_start}");
}

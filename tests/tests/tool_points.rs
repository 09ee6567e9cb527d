//! Several tool points per pose (issue 26 item 1): every tool point is carried by the same flows,
//! control point c is tool point c % m_p, and `evaluate_point` is exact.

use cbd_protocol::*;
use cbd_runtime::flow::control_points::{initial_state, integrate_control_points};
use cbd_runtime::flow::{Dims, FlowParams};
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
        let k0 =
            cbd_runtime::kinematics::forward_kinematics_at(&model.nominal, &x[6 * c..6 * c + 6], c % 3).normalised(&model.normalisation);
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
            let reference = model.normalisation.task_offset[a] + model.normalisation.task_scale * s[a];
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

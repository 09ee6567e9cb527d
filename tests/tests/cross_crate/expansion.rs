//! Format 5 end to end: the runtime's evaluation of the fields' expansions (docs/DESIGN.md §11) —
//! its exact Jacobian against finite differences, its agreement with the kernel form when the
//! expansion is built from the momenta analytically, the blob round trip, compensation on it, and
//! its storage.

use cbd_protocol::*;
use cbd_runtime::internals::expansion::{for_each_task_basis, joint_row_len, write_joint_basis};
use cbd_runtime::internals::flow::control_points::initial_state;
use cbd_runtime::internals::inverse_kinematics::nominal_position;
use cbd_runtime::{storage_len_for, Calibrator, Error};
use cbd_tests::{expansion_blob, joint_codes, lcg, six_joint_chain as six_joint, task_exponents};

use crate::finite_differences::worst_jacobian_errors;

fn storage_for(blob: &[u8]) -> Vec<f64> {
    vec![0.0; storage_len_for(&decode(blob).unwrap())]
}

/// Largest |FD − exact| relative to max |Dk1| over the queries.
fn exact_jacobian_error(blob: &[u8], queries: &[Vec<f64>]) -> f64 {
    let mut storage = storage_for(blob);
    let mut cal = Calibrator::load(blob, &mut storage).unwrap();
    worst_jacobian_errors(&mut cal, queries, 1e-6).0
}

#[test]
fn exact_jacobian_of_an_expansion_matches_finite_differences() {
    let mut s = 5u64;
    for (name, nominal, degrees) in [
        ("rr", NominalModel::planar(&[1.0, 0.5]).unwrap(), (6, 6)),
        ("dh-standard", six_joint(DhConvention::Standard), (2, 4)),
        ("dh-modified", six_joint(DhConvention::Modified), (2, 4)),
    ] {
        for integrator in
            [Integrator { method: IntegratorMethod::Euler, steps: 1 }, Integrator { method: IntegratorMethod::Heun, steps: 2 }]
        {
            let n = nominal.n_joints();
            let blob = expansion_blob(nominal.clone(), 30, integrator, 2.0, degrees, 0.05);
            let model = decode(&blob).unwrap();
            assert!(model.expansion.is_some());
            let queries: Vec<Vec<f64>> = (0..5).map(|_| (0..n).map(|_| 3.0 * lcg(&mut s)).collect()).collect();
            let exact = exact_jacobian_error(&blob, &queries);
            eprintln!("{name} {integrator:?}: exact Jacobian vs finite differences {exact:.1e} (relative to max |Dk1|)");
            assert!(exact < 1e-7, "{name} {integrator:?}: exact Jacobian off by {exact:e}");
        }
    }
}

/// e^{−b} I_h(b) by its series, Σ_k (b/2)^{2k+h} / (k! (k+h)!) e^{−b}.
fn scaled_bessel(h: u32, b: f64) -> f64 {
    let mut term = (0.5 * b).powi(h as i32) / (1..=h).map(|i| i as f64).product::<f64>();
    let mut sum = 0.0;
    for k in 0..60 {
        sum += term;
        term *= (0.5 * b) * (0.5 * b) / ((k + 1) as f64 * (k + 1 + h) as f64);
    }
    sum * (-b).exp()
}

/// An Euler × 1 Hamiltonian model with nearly flat kernels, and its expansion built from the momenta:
/// c_f = s γ λ_f Σ_j φ_f(x_j) J_jᵀ P_j, d_g = Σ_j ψ_g(k_j) P_j (k_j, J_j the runtime's initial state).
#[test]
fn an_expansion_built_from_the_momenta_reproduces_the_kernel_form() {
    let (n, m, n_points) = (2usize, 2usize, 24usize);
    let mut s = 17u64;
    let points: Vec<f64> = (0..n_points * n).map(|_| 3.0 * lcg(&mut s)).collect();
    let momenta: Vec<f64> = (0..n_points * m).map(|_| 0.02 * lcg(&mut s)).collect();
    let (pb, mb) = (f64_le_bytes(&points), f64_le_bytes(&momenta));
    let bs = [0.05, 0.08];
    let mut model = Model {
        nominal: NominalModel::planar(&[1.0, 0.5]).unwrap(),
        normalisation: Normalisation::IDENTITY,
        joint_kernel: JointKernel {
            gamma: 0.7,
            axes: heapless::Vec::from_slice(&[JointKernelAxis::Periodic { b: bs[0] }, JointKernelAxis::Periodic { b: bs[1] }]).unwrap(),
        },
        task_kernel: TaskKernel { width: 5.0 },
        integrator: Integrator { method: IntegratorMethod::Euler, steps: 1 },
        momentum_law: MomentumLaw::Hamiltonian,
        sigma: 1e-6,
        n_points: n_points as u32,
        points: F64Slice::from_le_bytes(&pb),
        momenta: F64Slice::from_le_bytes(&mb),
        expansion: None,
        noise_sigma: None,
        configuration_kernel: None,
        drift: None,
        provenance: None,
    };
    let kernel_blob = encode_to_vec(&model).unwrap();
    // Truncation: e^{−b} I_h(b) < 2e-16 for h > 8 at b ≤ 0.08; (|k|/a)^{2p}/p! < 1e-21 for p > 12 at |k| ≤ 1.5, a = 5.
    let codes = joint_codes(&model, 16).chunks(n).filter(|c| c.iter().all(|&v| v >> 1 <= 8)).flatten().copied().collect::<Vec<u8>>();
    let exponents = task_exponents(m, 12);
    let (r_v, r_w) = (codes.len() / n, exponents.len() / m);
    let mut state = vec![0.0; n_points * (2 * m + m * n)];
    initial_state(&model, &mut state).unwrap();
    let sign = model.momentum_law.joint_field_sign();
    let gamma = model.joint_kernel.gamma;
    let mut c = vec![0.0; r_v * n];
    let mut d = vec![0.0; r_w * m];
    let mut rows = vec![0.0; r_v * joint_row_len(n)];
    for j in 0..n_points {
        let st = &state[j * (2 * m + m * n)..(j + 1) * (2 * m + m * n)];
        let (k, jac, p) = (&st[..m], &st[m..m + m * n], &st[m + m * n..]);
        let u: Vec<f64> = (0..n).map(|e| (0..m).map(|a| jac[a * n + e] * p[a]).sum()).collect();
        write_joint_basis(&model.joint_kernel, &codes, n, &points[j * n..(j + 1) * n], &mut rows, false);
        for f in 0..r_v {
            let lambda: f64 = codes[f * n..(f + 1) * n]
                .iter()
                .zip(bs)
                .map(|(&code, b)| {
                    let h = (code >> 1) as u32;
                    scaled_bessel(h, b) * if h == 0 { 1.0 } else { 2.0 }
                })
                .product();
            let phi = rows[f * joint_row_len(n)];
            for e in 0..n {
                c[f * n + e] += sign * gamma * lambda * phi * u[e];
            }
        }
        for_each_task_basis(&model.task_kernel, &exponents, m, k, false, |g, psi, _, _| {
            for a in 0..m {
                d[g * m + a] += psi * p[a];
            }
        });
    }
    let weights: Vec<f64> = c.iter().chain(d.iter()).copied().collect();
    let wb = f64_le_bytes(&weights);
    model.expansion = Some(FieldExpansion {
        tolerance: 1e-15,
        task_radius: 1.5,
        n_joint_features: r_v as u32,
        joint_codes: &codes,
        n_task_features: r_w as u32,
        task_exponents: &exponents,
        weights: F64Slice::from_le_bytes(&wb),
    });
    let expansion_blob = encode_to_vec(&model).unwrap();
    let (mut sk, mut se) = (storage_for(&kernel_blob), storage_for(&expansion_blob));
    let mut kernel = Calibrator::load(&kernel_blob, &mut sk).unwrap();
    let mut expansion = Calibrator::load(&expansion_blob, &mut se).unwrap();
    let (mut worst_position, mut worst_jacobian, mut worst_deformation) = (0.0f64, 0.0f64, 0.0f64);
    for _ in 0..50 {
        let q: Vec<f64> = (0..n).map(|_| 3.2 * lcg(&mut s)).collect();
        let (a, b) = (kernel.evaluate(&q).unwrap(), expansion.evaluate(&q).unwrap());
        let diff = |x: &[f64], y: &[f64]| x.iter().zip(y).map(|(u, v)| (u - v) * (u - v)).sum::<f64>().sqrt();
        let norm = |x: &[f64]| x.iter().map(|u| u * u).sum::<f64>().sqrt();
        let (pa, pb): (Vec<f64>, Vec<f64>) = (a.position().iter().copied().collect(), b.position().iter().copied().collect());
        let (ja, jb): (Vec<f64>, Vec<f64>) = (a.jacobian().iter().copied().collect(), b.jacobian().iter().copied().collect());
        worst_position = worst_position.max(diff(&pa, &pb) / norm(&pa));
        worst_jacobian = worst_jacobian.max(diff(&ja, &jb) / norm(&ja));
        assert!((a.support() - b.support()).abs() <= 1e-12, "support {} vs {}", a.support(), b.support());
        // The deformation itself is not negligible: the comparison tests the fields.
        let k0 = cbd_runtime::internals::kinematics::forward_kinematics(&model.nominal, &q);
        worst_deformation = worst_deformation.max((0..m).map(|r| (a.position()[r] - k0.position[r]).abs()).fold(0.0, f64::max));
    }
    eprintln!("kernel form vs expansion: position {worst_position:.1e}, Jacobian {worst_jacobian:.1e} (relative); deformation up to {worst_deformation:.1e}");
    assert!(worst_deformation > 1e-3);
    assert!(worst_position < 1e-10 && worst_jacobian < 1e-10, "position {worst_position:e}, Jacobian {worst_jacobian:e}");
}

#[test]
fn an_expansion_blob_round_trips_and_compensate_reaches_its_targets() {
    for (nominal, degrees, reach) in
        [(NominalModel::planar(&[1.0, 0.5]).unwrap(), (6, 6), 1.5), (six_joint(DhConvention::Standard), (2, 4), 1000.0)]
    {
        let integrator = Integrator { method: IntegratorMethod::Heun, steps: 2 };
        let blob = expansion_blob(nominal, 30, integrator, 2.0, degrees, 0.05);
        let model = decode(&blob).unwrap();
        assert_eq!(encode_to_vec(&model).unwrap(), blob, "re-encoding gives the same bytes");
        assert_eq!(u16::from_le_bytes([blob[4], blob[5]]), 5);
        let mut storage = storage_for(&blob);
        let mut cal = Calibrator::load(&blob, &mut storage).unwrap();
        let nominal = cal.model().nominal.clone();
        let scale = cal.model().normalisation.task_scale;
        let n = nominal.n_joints();
        let mut s = 23u64;
        let (mut reached, count) = (0, 200);
        for _ in 0..count {
            let q_true: Vec<f64> = (0..n).map(|_| 2.5 * lcg(&mut s)).collect();
            let target: Vec<f64> = cal.evaluate(&q_true).unwrap().position().iter().copied().collect();
            let hint: Vec<f64> = q_true.iter().map(|q| q + 0.05 * lcg(&mut s)).collect();
            let mut seed = vec![0.0; n];
            nominal_position(&nominal, &target, &hint, &mut seed, 8, scale).unwrap();
            let mut q = vec![0.0; n];
            let c = cal.compensate(&target, &seed, &mut q).unwrap();
            let e = cal.evaluate(&q).unwrap();
            let miss = e.position().iter().zip(&target).map(|(a, b)| (a - b) * (a - b)).sum::<f64>().sqrt();
            assert!((miss - c.residual).abs() <= 1e-12 * reach);
            if miss <= 1e-9 * reach {
                reached += 1;
            }
        }
        let fraction = reached as f64 / count as f64;
        eprintln!("{n} joints: {fraction:.3} of targets within 1e-9 of reach");
        assert!(fraction >= 0.97, "only {fraction} reached");
    }
}

#[test]
fn storage_is_exactly_what_the_model_needs() {
    let integrator = Integrator { method: IntegratorMethod::Heun, steps: 2 };
    for nominal in [NominalModel::planar(&[1.0, 0.5]).unwrap(), six_joint(DhConvention::Modified)] {
        let blob = expansion_blob(nominal, 30, integrator, 2.0, (2, 3), 0.05);
        let model = decode(&blob).unwrap();
        let needed = storage_len_for(&model);
        let mut storage = vec![0.0; needed - 1];
        assert_eq!(Calibrator::from_model(model.clone(), &mut storage).err(), Some(Error::StorageTooSmall { needed, got: needed - 1 }));
        let mut storage = vec![0.0; needed];
        let mut cal = Calibrator::from_model(model.clone(), &mut storage).unwrap();
        let q = vec![0.3; model.n_joints()];
        assert!(cal.evaluate(&q).is_ok());
        // The kernel form of the same blob needs its own figure (and is not smaller here).
        let mut kernel_form = model.clone();
        kernel_form.expansion = None;
        let kernel = storage_len_for(&kernel_form);
        assert_eq!(kernel, cbd_runtime::storage_len(model.n_points as usize, model.n_joints(), model.task_dim(), model.integrator));
    }
}

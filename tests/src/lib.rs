//! Cross-crate tests live in `tests/`; this library holds the fixtures they share.

use cbd_protocol::*;

/// The blob of the independent reference flow (`data/rr_flow_reference.json`, see
/// `data/REFERENCE.md`): the RR arm, 256 grid points, the given momenta P0, Heun × 5 (~8 kB).
pub fn reference_blob() -> Vec<u8> {
    let text = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/data/rr_flow_reference.json")).expect("reference data");
    let v: serde_json::Value = serde_json::from_str(&text).expect("reference JSON");
    let flat = |key: &str| -> Vec<f64> {
        v[key].as_array().into_iter().flatten().flat_map(|r| r.as_array().into_iter().flatten().filter_map(|x| x.as_f64())).collect()
    };
    let (x, p) = (f64_le_bytes(&flat("X")), f64_le_bytes(&flat("P0")));
    let model = Model {
        nominal: NominalModel::planar(&cbd_protocol::paper_rr::LENGTHS).expect("two links"),
        normalisation: Normalisation::IDENTITY,
        joint_kernel: cbd_protocol::paper_rr::joint_kernel(),
        task_kernel: cbd_protocol::paper_rr::task_kernel(),
        integrator: Integrator { method: IntegratorMethod::Heun, steps: 5 },
        momentum_law: MomentumLaw::WithDivergence,
        sigma: 1e-4,
        n_points: 256,
        points: F64Slice::from_le_bytes(&x),
        momenta: F64Slice::from_le_bytes(&p),
        expansion: None,
        noise_sigma: None,
        configuration_kernel: None,
        drift: None,
        provenance: None,
    };
    encode_to_vec(&model).expect("the reference model encodes")
}

/// A deterministic pseudo-random number in [−1, 1) (64-bit LCG), for test inputs.
pub fn lcg(state: &mut u64) -> f64 {
    *state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
    ((*state >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
}

/// A blob of `nominal` (its effects included) with `n_points` pseudo-random configurations and
/// momenta of size `momentum`; prismatic joints get a Gaussian kernel of `prismatic_width`.
pub fn model_blob(nominal: NominalModel, n_points: usize, momentum: f64, integrator: Integrator, prismatic_width: f64) -> Vec<u8> {
    let n = nominal.n_joints();
    let m = nominal.task_dim();
    let mut s = 7u64;
    let points: Vec<f64> = (0..n_points * n).map(|_| 3.0 * lcg(&mut s)).collect();
    let momenta: Vec<f64> = (0..n_points * m).map(|_| momentum * lcg(&mut s)).collect();
    let axes: heapless::Vec<JointKernelAxis, { cbd_protocol::MAX_JOINTS }> = (0..n)
        .map(|d| {
            if nominal.is_revolute(d) {
                JointKernelAxis::Periodic { b: 1.0 }
            } else {
                JointKernelAxis::Gaussian { width: prismatic_width }
            }
        })
        .collect();
    let (pb, mb) = (f64_le_bytes(&points), f64_le_bytes(&momenta));
    let normalisation = if m == 3 { Normalisation { task_offset: [0.0, 0.0, 300.0], task_scale: 500.0 } } else { Normalisation::IDENTITY };
    let model = Model {
        nominal,
        normalisation,
        joint_kernel: JointKernel { gamma: 2.0, axes },
        task_kernel: TaskKernel { width: 0.8 },
        integrator,
        momentum_law: MomentumLaw::WithDivergence,
        sigma: 1e-3,
        n_points: n_points as u32,
        points: F64Slice::from_le_bytes(&pb),
        momenta: F64Slice::from_le_bytes(&mb),
        expansion: None,
        noise_sigma: None,
        configuration_kernel: None,
        drift: None,
        provenance: None,
    };
    encode_to_vec(&model).expect("the test model encodes")
}

/// Joint codes of every product basis function of total degree ≤ `degree` (multi-indices h with
/// Σ h_d ≤ degree, lexicographic; periodic axes cos and sin of each h > 0, Gaussian axes k = h).
pub fn joint_codes(model: &Model<'_>, degree: u8) -> Vec<u8> {
    let n = model.n_joints();
    let mut out = Vec::new();
    let mut h = vec![0u8; n];
    loop {
        if h.iter().map(|&v| v as u32).sum::<u32>() <= degree as u32 {
            // Every choice of cos/sin on the periodic axes with h > 0.
            let free: Vec<usize> =
                (0..n).filter(|&d| h[d] > 0 && matches!(model.joint_kernel.axes[d], JointKernelAxis::Periodic { .. })).collect();
            for mask in 0..(1u32 << free.len()) {
                let mut code: Vec<u8> = h.iter().map(|&v| v << 1).collect();
                for (i, &d) in free.iter().enumerate() {
                    code[d] |= ((mask >> i) & 1) as u8;
                }
                out.extend_from_slice(&code);
            }
        }
        // Next multi-index (odometer, each digit 0..=degree).
        let mut d = n;
        loop {
            if d == 0 {
                return out;
            }
            d -= 1;
            if h[d] < degree {
                h[d] += 1;
                break;
            }
            h[d] = 0;
        }
    }
}

/// Task exponents of every monomial of total degree ≤ `degree` in m coordinates (lexicographic).
pub fn task_exponents(m: usize, degree: u8) -> Vec<u8> {
    let mut out = Vec::new();
    let mut a = vec![0u8; m];
    loop {
        if a.iter().map(|&v| v as u32).sum::<u32>() <= degree as u32 {
            out.extend_from_slice(&a);
        }
        let mut c = m;
        loop {
            if c == 0 {
                return out;
            }
            c -= 1;
            if a[c] < degree {
                a[c] += 1;
                break;
            }
            a[c] = 0;
        }
    }
}

/// The blob of [`model_blob`]'s model with an expansion: joint codes of total degree ≤
/// `joint_degree`, task exponents of total degree ≤ `task_degree`, and weights of size `scale`
/// from a fixed pseudo-random sequence, damped by 1 + degree.
pub fn expansion_blob(
    nominal: NominalModel,
    n_points: usize,
    integrator: Integrator,
    prismatic_width: f64,
    (joint_degree, task_degree): (u8, u8),
    scale: f64,
) -> Vec<u8> {
    let base = model_blob(nominal, n_points, 0.01, integrator, prismatic_width);
    let model = decode(&base).expect("the base model decodes");
    let codes = joint_codes(&model, joint_degree);
    let exponents = task_exponents(model.task_dim(), task_degree);
    let mut s = 11u64;
    encode_with_synthetic_expansion(&model, &codes, &exponents, scale, || lcg(&mut s)).expect("the expansion model encodes")
}

/// A six-joint DH chain in mm with a prismatic third joint, every joint's zero offset 0.1 rad, a
/// rotated and shifted base and an offset tool: the chain the runtime's Jacobian and expansion tests
/// share, in either convention.
pub fn six_joint_chain(convention: DhConvention) -> NominalModel {
    use std::f64::consts::FRAC_PI_2;
    let j = |kind, a: f64, alpha: f64, d: f64| DhJoint { kind, a, alpha, d, theta_offset: 0.1 };
    let mut tool = Transform::IDENTITY;
    tool.translation = [10.0, 20.0, 31.0];
    NominalModel::DhChain(DhChain {
        convention,
        joints: heapless::Vec::from_slice(&[
            j(JointKind::Revolute, 0.0, FRAC_PI_2, 89.0),
            j(JointKind::Revolute, -425.0, 0.0, 0.0),
            j(JointKind::Prismatic, -392.0, 0.2, 0.0),
            j(JointKind::Revolute, 0.0, FRAC_PI_2, 109.0),
            j(JointKind::Revolute, 0.0, -FRAC_PI_2, 94.0),
            j(JointKind::Revolute, 0.0, 0.0, 82.0),
        ])
        .unwrap(),
        base: Transform { rotation: [0.0, -1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0], translation: [100.0, 0.0, 200.0] },
        tool,
        effects: Effects::NONE,
        tool_points: heapless::Vec::new(),
    })
}

//! The test blobs of the firmware check, built deterministically (shared with `examples/control_loop`
//! through `#[path]`).

use cbd_protocol::*;
use serde_json::Value;
use std::f64::consts::PI;

use crate::shared::Lcg;

const RR_REFERENCE: &str = include_str!("../../../tests/data/rr_flow_reference.json");

/// The paper's RR arm settings, exactly as `tests/tests/cross_crate/reference_flow.rs` builds them.
fn rr_model<'a>(points: &'a [u8], momenta: &'a [u8], n_points: u32, integrator: Integrator) -> Model<'a> {
    Model {
        nominal: NominalModel::planar(&cbd_protocol::paper_rr::LENGTHS).expect("2 joints"),
        normalisation: Normalisation::IDENTITY,
        joint_kernel: cbd_protocol::paper_rr::joint_kernel(),
        task_kernel: cbd_protocol::paper_rr::task_kernel(),
        integrator,
        momentum_law: MomentumLaw::WithDivergence,
        sigma: 1.0,
        n_points,
        points: F64Slice::from_le_bytes(points),
        momenta: F64Slice::from_le_bytes(momenta),
        expansion: None,
        noise_sigma: None,
        configuration_kernel: None,
        drift: None,
        provenance: None,
    }
}

fn flat(v: &Value, out: &mut Vec<f64>) {
    match v {
        Value::Array(a) => a.iter().for_each(|x| flat(x, out)),
        Value::Number(n) => out.push(n.as_f64().expect("number")),
        _ => panic!("unexpected JSON value in the RR reference"),
    }
}

/// The scheme `cbd demo` trains (and the cost blobs use): Euler × 2 steps.
pub const DEMO_SCHEME: Integrator = Integrator { method: IntegratorMethod::Euler, steps: 2 };

/// The RR benchmark: 16 × 16 grid and the reference momenta of `tests/data/rr_flow_reference.json`, Heun × 5.
pub fn rr_reference_blob() -> Vec<u8> {
    let reference: Value = serde_json::from_str(RR_REFERENCE).expect("RR reference JSON");
    let (mut x, mut p0) = (Vec::new(), Vec::new());
    flat(&reference["X"], &mut x);
    flat(&reference["P0"], &mut p0);
    assert_eq!((x.len(), p0.len()), (512, 512));
    let (pb, mb) = (f64_le_bytes(&x), f64_le_bytes(&p0));
    encode_to_vec(&rr_model(&pb, &mb, 256, Integrator { method: IntegratorMethod::Heun, steps: 5 })).expect("encode RR blob")
}

/// RR arm on a side × side grid of the torus with small pseudo-random momenta and `scheme`
/// (cost measurement: the evaluation has no data-dependent branches, so the momenta do not matter).
pub fn rr_grid_blob(side: usize, seed: u32, scheme: Integrator) -> Vec<u8> {
    let step = 2.0 * PI / side as f64;
    let x: Vec<f64> = (0..side * side).flat_map(|k| [(k / side) as f64 * step, (k % side) as f64 * step]).collect();
    let mut rng = Lcg(seed);
    let p0: Vec<f64> = (0..2 * side * side).map(|_| 1e-3 * rng.symmetric()).collect();
    let (pb, mb) = (f64_le_bytes(&x), f64_le_bytes(&p0));
    encode_to_vec(&rr_model(&pb, &mb, (side * side) as u32, scheme)).expect("encode RR grid blob")
}

/// A 6-joint model: UR5 standard DH table (mm, data/ur5/README.md), 64 random configurations,
/// small pseudo-random momenta, Heun × 5.
pub fn six_joint_blob() -> Vec<u8> {
    six_joint_blob_with(cbd_protocol::Effects::NONE)
}

/// [`six_joint_blob`] with physical effects of all five types on the chain: encoder scale,
/// transmission harmonics, gravity compliance (tilted gravity, UR5 link masses), link bending and
/// gravity moments (compliance-weighted masses off the link ends, format 4), sized like a real
/// arm's (joint deflections of about a milliradian, bending of 0.05–0.1 mm).
pub fn six_effects_blob() -> Vec<u8> {
    let (s, c) = (0.05f64, (1.0f64 - 0.05 * 0.05).sqrt());
    let gravity = GravityModel {
        direction: [0.0, s, -c],
        link_masses: heapless::Vec::from_slice(&[3.7, 8.393, 2.275, 1.219, 1.219, 0.1879]).expect("6 masses"),
    };
    let list = [
        Effect::EncoderScale { joint: 0, scale: 1.5e-3 },
        Effect::EncoderScale { joint: 3, scale: -8e-4 },
        Effect::Transmission { joint: 1, harmonic: 2, cos: 4e-4, sin: -2.5e-4 },
        Effect::Transmission { joint: 4, harmonic: 1, cos: -3e-4, sin: 6e-4 },
        Effect::Transmission { joint: 5, harmonic: 3, cos: 1e-4, sin: 1e-4 },
        Effect::GravityCompliance { joint: 1, compliance: 8e-8 },
        Effect::GravityCompliance { joint: 2, compliance: 1.2e-7 },
        Effect::GravityCompliance { joint: 3, compliance: 3e-7 },
        Effect::LinkBending { link: 1, compliance: 0.1 },
        Effect::LinkBending { link: 2, compliance: 0.06 },
        Effect::GravityMoment { joint: 1, link: 2, mass: 1e-6, first_moment: [2e-4, 0.0, 1e-4] },
        Effect::GravityMoment { joint: 4, link: 5, mass: 1e-6, first_moment: [0.0, 3e-5, -2e-5] },
    ];
    six_joint_blob_with(Effects { gravity, list: heapless::Vec::from_slice(&list).expect("fits MAX_EFFECTS") })
}

fn six_joint_blob_with(effects: Effects) -> Vec<u8> {
    let chain = DhChain { effects, ..cbd_protocol::ur5::chain() };
    let integrator = Integrator { method: IntegratorMethod::Heun, steps: 5 };
    dh_chain_blob(chain, [0.0, 0.0, 400.0], 500.0, integrator, 0x0005_5e1f, None)
}

/// The scheme of the configuration-dependent task field (format 8, docs/DESIGN.md §16): Euler × 1.
const CONFIGURATION_SCHEME: Integrator = Integrator { method: IntegratorMethod::Euler, steps: 1 };

/// The 6-joint model ([`six_joint_blob`]'s chain, points and momenta) with the configuration-dependent
/// task field (format 8, docs/DESIGN.md §16): γ_C = 0.5, b = 2 on every axis, task width 0.5
/// (internal units), Euler × 1, noise σ 0.05 mm.
pub fn six_configuration_blob() -> Vec<u8> {
    let kernel = ConfigurationKernel {
        gamma: 0.5,
        axes: heapless::Vec::from_slice(&[JointKernelAxis::Periodic { b: 2.0 }; 6]).expect("6 axes"),
        task_width: Some(0.5),
    };
    dh_chain_blob(cbd_protocol::ur5::chain(), [0.0, 0.0, 400.0], 500.0, CONFIGURATION_SCHEME, 0x0005_5e1f, Some(kernel))
}

/// [`six_configuration_blob`] without the term (same chain, points, momenta and scheme): its cost's
/// reference.
pub fn six_euler1_blob() -> Vec<u8> {
    dh_chain_blob(cbd_protocol::ur5::chain(), [0.0, 0.0, 400.0], 500.0, CONFIGURATION_SCHEME, 0x0005_5e1f, None)
}

/// examples/chain10/chain10.toml's table (mm; a torso carrying a seven-joint arm), 64 random
/// configurations, small pseudo-random momenta, Heun × 2: the firmware check's longest chain
/// (issue 26 item 4).
pub fn chain10_blob() -> Vec<u8> {
    const H: f64 = core::f64::consts::FRAC_PI_2;
    let rows = [
        (0.0, -H, 350.0),
        (120.0, H, 0.0),
        (0.0, -H, 280.0),
        (180.0, -H, 0.0),
        (0.0, H, 0.0),
        (0.0, H, 400.0),
        (0.0, -H, 0.0),
        (0.0, -H, 400.0),
        (0.0, H, 0.0),
        (0.0, 0.0, 126.0),
    ];
    let joints = rows.map(|(a, alpha, d)| DhJoint { kind: JointKind::Revolute, a, alpha, d, theta_offset: 0.0 });
    let mut tool = Transform::IDENTITY;
    tool.translation = [0.0, 0.0, 31.0];
    let chain = DhChain {
        convention: DhConvention::Standard,
        joints: heapless::Vec::from_slice(&joints).expect("10 joints fit MAX_JOINTS"),
        base: Transform::IDENTITY,
        tool,
        effects: Effects::NONE,
        tool_points: heapless::Vec::new(),
    };
    let integrator = Integrator { method: IntegratorMethod::Heun, steps: 2 };
    dh_chain_blob(chain, [0.0, 0.0, 600.0], 800.0, integrator, 0x000c_4a10, None)
}

/// The UR5 (mm) with three tool points 100 mm apart (format 6, issue 26 item 1): 21 poses, each
/// configuration repeated for its three control points, small pseudo-random momenta, Heun × 5.
/// One of the firmware check's blobs (poses printed as `qp` lines) and the C library's tests.
pub fn six_tool_points_blob() -> Vec<u8> {
    const POSES: usize = 21;
    let mut chain = cbd_protocol::ur5::chain();
    chain.tool_points = heapless::Vec::from_slice(&[[0.0, 0.0, 0.0], [100.0, 0.0, 0.0], [0.0, 100.0, 0.0]]).expect("3 ≤ MAX_TOOL_POINTS");
    let mut rng = Lcg(0x0007_0013);
    let mut x = Vec::new();
    for _ in 0..POSES {
        let q: Vec<f64> = (0..6).map(|_| PI * rng.symmetric()).collect();
        for _ in 0..3 {
            x.extend_from_slice(&q);
        }
    }
    let p0: Vec<f64> = (0..POSES * 3 * 3).map(|_| 1e-3 * rng.symmetric()).collect();
    let (pb, mb) = (f64_le_bytes(&x), f64_le_bytes(&p0));
    let model = Model {
        nominal: NominalModel::DhChain(chain),
        normalisation: Normalisation { task_offset: [0.0, 0.0, 400.0], task_scale: 500.0 },
        joint_kernel: JointKernel {
            gamma: 1.0,
            axes: heapless::Vec::from_slice(&[JointKernelAxis::Periodic { b: 1.0 }; 6]).expect("6 axes"),
        },
        task_kernel: TaskKernel { width: 1.0 },
        integrator: Integrator { method: IntegratorMethod::Heun, steps: 5 },
        momentum_law: MomentumLaw::Hamiltonian,
        sigma: 1.0,
        n_points: (POSES * 3) as u32,
        points: F64Slice::from_le_bytes(&pb),
        momenta: F64Slice::from_le_bytes(&mb),
        expansion: None,
        noise_sigma: None,
        configuration_kernel: None,
        drift: None,
        provenance: None,
    };
    encode_to_vec(&model).expect("encode the tool-points blob")
}

/// A kernel-form blob on `chain`: 64 configurations uniform on the torus, momenta ~1e-3, periodic
/// joint kernel (b = 1 on every axis), the trainer's default momentum law; with `configuration`
/// also the configuration-dependent task field and the noise σ (0.05 mm) its format needs.
fn dh_chain_blob(
    chain: DhChain,
    task_offset: [f64; 3],
    task_scale: f64,
    integrator: Integrator,
    seed: u32,
    configuration: Option<ConfigurationKernel>,
) -> Vec<u8> {
    const N: usize = 64;
    let n = chain.joints.len();
    let mut rng = Lcg(seed);
    let x: Vec<f64> = (0..N * n).map(|_| PI * rng.symmetric()).collect();
    let p0: Vec<f64> = (0..N * 3).map(|_| 1e-3 * rng.symmetric()).collect();
    let (pb, mb) = (f64_le_bytes(&x), f64_le_bytes(&p0));
    let axes = heapless::Vec::from_slice(&[JointKernelAxis::Periodic { b: 1.0 }; MAX_JOINTS][..n]).expect("n ≤ MAX_JOINTS axes");
    let model = Model {
        nominal: NominalModel::DhChain(chain),
        normalisation: Normalisation { task_offset, task_scale },
        joint_kernel: JointKernel { gamma: 1.0, axes },
        task_kernel: TaskKernel { width: 1.0 },
        integrator,
        // The trainer's default law (v = −K_V Jᵀ P, format 3), so the firmware check covers it.
        momentum_law: MomentumLaw::Hamiltonian,
        sigma: 1.0,
        n_points: N as u32,
        points: F64Slice::from_le_bytes(&pb),
        momenta: F64Slice::from_le_bytes(&mb),
        expansion: None,
        noise_sigma: configuration.as_ref().map(|_| 0.05),
        configuration_kernel: configuration,
        drift: None,
        provenance: None,
    };
    encode_to_vec(&model).expect("encode a DH-chain blob")
}

/// Joint codes of every product basis function of total degree ≤ `degree` (multi-indices h with
/// Σ h_d ≤ degree, lexicographic; cos and sin of each h > 0 on the periodic axes; all axes periodic).
fn periodic_codes(n: usize, degree: u8) -> Vec<u8> {
    let mut out = Vec::new();
    let mut h = vec![0u8; n];
    loop {
        if h.iter().map(|&v| v as u32).sum::<u32>() <= degree as u32 {
            let free: Vec<usize> = (0..n).filter(|&d| h[d] > 0).collect();
            for mask in 0..(1u32 << free.len()) {
                let mut code: Vec<u8> = h.iter().map(|&v| v << 1).collect();
                for (i, &d) in free.iter().enumerate() {
                    code[d] |= ((mask >> i) & 1) as u8;
                }
                out.extend_from_slice(&code);
            }
        }
        if !odometer(&mut h, degree) {
            return out;
        }
    }
}

/// Exponents of every monomial of total degree ≤ `degree` in m coordinates (lexicographic).
fn monomial_exponents(m: usize, degree: u8) -> Vec<u8> {
    let mut out = Vec::new();
    let mut a = vec![0u8; m];
    loop {
        if a.iter().map(|&v| v as u32).sum::<u32>() <= degree as u32 {
            out.extend_from_slice(&a);
        }
        if !odometer(&mut a, degree) {
            return out;
        }
    }
}

/// The next multi-index with digits 0..=max (false after the last).
fn odometer(digits: &mut [u8], max: u8) -> bool {
    for d in digits.iter_mut().rev() {
        if *d < max {
            *d += 1;
            return true;
        }
        *d = 0;
    }
    false
}

/// `model` with an expansion (format 5, docs/DESIGN.md §11) of joint degree ≤ `joint_degree`,
/// task degree ≤ `task_degree` and weights of size `scale` (damped by 1 + degree) from `seed`'s
/// pseudo-random sequence: the evaluation's cost and bits do not depend on the values.
fn with_expansion(model: &Model<'_>, (joint_degree, task_degree): (u8, u8), scale: f64, seed: u32) -> Vec<u8> {
    let (n, m) = (model.n_joints(), model.task_dim());
    let mut rng = Lcg(seed);
    encode_with_synthetic_expansion(model, &periodic_codes(n, joint_degree), &monomial_exponents(m, task_degree), scale, || rng.symmetric())
        .expect("encode expansion blob")
}

/// RR arm in the kernels' own basis: the 8 × 8 grid's kernel form (the reference) and an expansion
/// of 113 joint functions (degree ≤ 7) and 28 task functions (degree ≤ 6), Euler × 1.
pub fn rr_ws_blob() -> Vec<u8> {
    let base = rr_grid_blob(8, 0x0000_0064, Integrator { method: IntegratorMethod::Euler, steps: 1 });
    let model = decode(&base).expect("RR grid blob");
    with_expansion(&model, (7, 6), 1e-3, 0x0000_0777)
}

/// The 6-joint model ([`six_joint_blob`]'s chain and points) in the kernels' own basis: 85 joint
/// functions (degree ≤ 2) and 35 task functions (degree ≤ 4), Heun × 2.
pub fn six_ws_blob() -> Vec<u8> {
    let base = six_joint_blob();
    let mut model = decode(&base).expect("6-joint blob");
    model.integrator = Integrator { method: IntegratorMethod::Heun, steps: 2 };
    with_expansion(&model, (2, 4), 1e-3, 0x0006_0777)
}

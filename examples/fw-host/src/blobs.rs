//! The test blobs of the firmware check, built deterministically (shared with `examples/control_loop`
//! through `#[path]`).

use cbd_protocol::*;
use serde_json::Value;
use std::f64::consts::PI;

use crate::shared::Lcg;

const RR_REFERENCE: &str = include_str!("../../../tests/data/rr_flow_reference.json");

/// The paper's RR arm settings, exactly as `tests/tests/reference_flow.rs` builds them.
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
    const N: usize = 64;
    let mut rng = Lcg(0x0005_5e1f);
    let x: Vec<f64> = (0..N * 6).map(|_| PI * rng.symmetric()).collect();
    let p0: Vec<f64> = (0..N * 3).map(|_| 1e-3 * rng.symmetric()).collect();
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
        // The trainer's default law (v = −K_V Jᵀ P, format 3), so the firmware check covers it.
        momentum_law: MomentumLaw::Hamiltonian,
        sigma: 1.0,
        n_points: N as u32,
        points: F64Slice::from_le_bytes(&pb),
        momenta: F64Slice::from_le_bytes(&mb),
        expansion: None,
    };
    encode_to_vec(&model).expect("encode 6-joint blob")
}

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
    let axes: heapless::Vec<JointKernelAxis, 7> = (0..n)
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
    };
    encode_to_vec(&model).expect("the test model encodes")
}

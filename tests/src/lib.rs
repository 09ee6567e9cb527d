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
        nominal: NominalModel::planar(&[1.0, 0.5]).expect("two links"),
        normalisation: Normalisation::IDENTITY,
        joint_kernel: JointKernel {
            gamma: 8.0,
            axes: heapless::Vec::from_slice(&[JointKernelAxis::Periodic { b: 1.0186 }; 2]).expect("two axes"),
        },
        task_kernel: TaskKernel { width: 1.027 },
        integrator: Integrator { method: IntegratorMethod::Heun, steps: 5 },
        momentum_law: MomentumLaw::WithDivergence,
        sigma: 1e-4,
        n_points: 256,
        points: F64Slice::from_le_bytes(&x),
        momenta: F64Slice::from_le_bytes(&p),
    };
    encode_to_vec(&model).expect("the reference model encodes")
}

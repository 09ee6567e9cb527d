//! The runtime's discrete flow against independent float64 reference values
//! (`data/rr_flow_reference.json`, see `data/REFERENCE.md`): RK4 × 10 and Heun × 5 steps.

use cbd_protocol::*;
use cbd_runtime::internals::flow::control_points::{initial_state, integrate_control_points};
use cbd_runtime::internals::flow::{Dims, FlowParams};
use cbd_runtime::Calibrator;
use serde_json::Value;

fn matrix(v: &Value) -> Vec<Vec<f64>> {
    v.as_array().unwrap().iter().map(|r| r.as_array().unwrap().iter().map(|x| x.as_f64().unwrap()).collect()).collect()
}

fn flat(v: &Value) -> Vec<f64> {
    fn walk(v: &Value, out: &mut Vec<f64>) {
        match v {
            Value::Array(a) => a.iter().for_each(|x| walk(x, out)),
            Value::Number(n) => out.push(n.as_f64().unwrap()),
            _ => panic!("unexpected value"),
        }
    }
    let mut out = Vec::new();
    walk(v, &mut out);
    out
}

fn rr_model<'a>(points: &'a [u8], momenta: &'a [u8], n_points: u32, method: IntegratorMethod, steps: u16) -> Model<'a> {
    Model {
        nominal: NominalModel::planar(&cbd_protocol::paper_rr::LENGTHS).unwrap(),
        normalisation: Normalisation::IDENTITY,
        joint_kernel: cbd_protocol::paper_rr::joint_kernel(),
        task_kernel: cbd_protocol::paper_rr::task_kernel(),
        integrator: Integrator { method, steps },
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

fn max_rel_diff(a: &[f64], b: &[f64]) -> f64 {
    assert_eq!(a.len(), b.len());
    let scale = b.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    a.iter().zip(b).fold(0.0f64, |m, (x, y)| m.max((x - y).abs())) / scale
}

#[test]
fn runtime_matches_independent_reference() {
    let text = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/data/rr_flow_reference.json")).unwrap();
    let reference: Value = serde_json::from_str(&text).unwrap();
    let x = flat(&reference["X"]);
    let p0 = flat(&reference["P0"]);
    let queries = matrix(&reference["queries"]);
    let (pb, mb) = (f64_le_bytes(&x), f64_le_bytes(&p0));
    for (key, method, steps) in [("rk4_10", IntegratorMethod::Rk4, 10), ("heun_5", IntegratorMethod::Heun, 5)] {
        let model = rr_model(&pb, &mb, 256, method, steps);
        let dims = Dims { n: 2, m: 2 };
        let mut state = vec![0.0; 256 * dims.state_len()];
        initial_state(&model, &mut state).unwrap();
        let mut scratch = vec![0.0; 3 * state.len()];
        let mut traj = vec![0.0; model.integrator.stage_count() * 256 * dims.sample_len()];
        let params = FlowParams { dims, joint_kernel: &model.joint_kernel, task_kernel: &model.task_kernel, law: model.momentum_law };
        integrate_control_points(&params, model.integrator, &x, &mut state, &mut scratch, &mut traj, |_, _| {}).unwrap();
        let pick =
            |range: std::ops::Range<usize>| state.chunks(dims.state_len()).flat_map(|s| s[range.clone()].to_vec()).collect::<Vec<_>>();
        let r = &reference[key];
        let dk = max_rel_diff(&pick(0..2), &flat(&r["k1"]));
        let dj = max_rel_diff(&pick(2..6), &flat(&r["J1"]));
        let dp = max_rel_diff(&pick(6..8), &flat(&r["P1"]));
        assert!(dk < 1e-12 && dj < 1e-12 && dp < 1e-12, "{key}: k {dk:e} J {dj:e} P {dp:e}");

        let blob = encode_to_vec(&model).unwrap();
        let mut storage = vec![0.0; cbd_runtime::storage_len(256, 2, 2, model.integrator)];
        let mut cal = Calibrator::load(&blob, &mut storage).unwrap();
        let got: Vec<f64> = queries.iter().flat_map(|q| cal.evaluate(q).unwrap().position().iter().copied().collect::<Vec<_>>()).collect();
        let dq = max_rel_diff(&got, &flat(&r["query_k1"]));
        assert!(dq < 1e-12, "{key}: queries {dq:e}");
        eprintln!("{key}: k {dk:e} J {dj:e} P {dp:e} queries {dq:e}");
    }
}

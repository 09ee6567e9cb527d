//! The runtime's exact Jacobian against central finite differences of its own positions, for the
//! planar RR arm and for 6-joint DH chains (standard and modified, with a prismatic joint).

use cbd_protocol::*;
use cbd_runtime::internals::flow::query_derivatives::nominal_hessian;
use cbd_runtime::Calibrator;
use cbd_tests::{lcg, model_blob, six_joint_chain as six_joint};

use crate::finite_differences::worst_jacobian_errors;

fn check(blob: &[u8], queries: &[Vec<f64>]) -> (f64, f64) {
    let mut storage = vec![0.0; 200_000];
    let mut cal = Calibrator::load(blob, &mut storage).unwrap();
    worst_jacobian_errors(&mut cal, queries, 1e-6)
}

#[test]
fn exact_jacobian_matches_finite_differences() {
    let mut s = 3u64;
    for (name, nominal, momentum) in [
        ("rr", NominalModel::planar(&[1.0, 0.5]).unwrap(), 0.05),
        ("dh-standard", six_joint(DhConvention::Standard), 0.02),
        ("dh-modified", six_joint(DhConvention::Modified), 0.02),
    ] {
        for integrator in [Integrator { method: IntegratorMethod::Euler, steps: 2 }, Integrator { method: IntegratorMethod::Rk4, steps: 3 }]
        {
            let n = nominal.n_joints();
            let blob = model_blob(nominal.clone(), 40, momentum, integrator, 2.0);
            let queries: Vec<Vec<f64>> = (0..5).map(|_| (0..n).map(|_| 3.0 * lcg(&mut s)).collect()).collect();
            let (exact, transported) = check(&blob, &queries);
            eprintln!("{name} {integrator:?}: exact {exact:.1e}, transported J(1) {transported:.1e} (relative to max |Dk1|)");
            assert!(exact < 1e-7, "{name}: exact Jacobian off by {exact:e}");
        }
    }
}

#[test]
fn nominal_hessian_matches_finite_differences() {
    for nominal in [six_joint(DhConvention::Standard), six_joint(DhConvention::Modified)] {
        let x = [0.3, -0.8, 0.05, 1.2, -0.4, 2.0];
        let h = nominal_hessian(&nominal, &x);
        let step = 1e-6;
        for d in 0..6 {
            let (mut xa, mut xb) = (x, x);
            xa[d] += step;
            xb[d] -= step;
            let (ja, jb) = (
                cbd_runtime::internals::kinematics::forward_kinematics(&nominal, &xa).jacobian,
                cbd_runtime::internals::kinematics::forward_kinematics(&nominal, &xb).jacobian,
            );
            for a in 0..3 {
                for e in 0..6 {
                    let fd = (ja[a][e] - jb[a][e]) / (2.0 * step);
                    assert!((fd - h[a][e][d]).abs() < 1e-5 * (1.0 + fd.abs()), "a {a} e {e} d {d}: fd {fd} vs {}", h[a][e][d]);
                }
            }
        }
    }
}

//! The large-N solver searches K_lin's dominant eigenspace only. Its optimum must be one of the
//! full problem too: from it, a Gauss–Newton step over all N·m momenta (dense Jacobian and QR)
//! must gain (almost) nothing. Slow (about 20 s in release): `cargo test --release -- --ignored`.

use cbd_trainer::flow::tangent::position_jacobian;
use cbd_trainer::flow::ControlPoints;
use cbd_trainer::simulate::{configurations, rr, Sampling};
use cbd_trainer::solver::regulariser::regulariser_matrix;
use cbd_trainer::solver::step::{DampingScale, StepFactor};
use cbd_trainer::solver::{fit_cbd, CbdOptions};
use faer::Par;

#[test]
#[ignore = "slow: N = 1024 fit plus a dense Jacobian; run with --ignored"]
fn eigenspace_optimum_is_a_full_space_optimum_at_n_1024() {
    let data = rr::RealRr::default().measure(&configurations(Sampling::Grid { per_axis: 32 }, 2));
    let opts = CbdOptions::paper_rr();
    let fit = fit_cbd(&rr::nominal(), &data, &opts).expect("fit");
    assert_eq!(fit.report.method, "eigenspace", "auto picks the eigenspace at N = 1024");
    let o = &opts;
    let cp = ControlPoints::new(
        &rr::nominal(),
        &o.normalisation,
        data.joints.clone(),
        o.joint_kernel.clone(),
        o.task_kernel,
        o.solver.law,
        o.integrator,
    );
    let k = regulariser_matrix(&cp);
    let energy = |p: &[f64]| -> (f64, Vec<f64>, cbd_trainer::flow::PrimalFlow) {
        let flow = cp.integrate(p).unwrap();
        let r: Vec<f64> = flow.positions(cp.dims).iter().zip(&data.positions).map(|(a, b)| (a - b) / o.sigma).collect();
        let mut reg = 0.0;
        for (j, pj) in p.iter().enumerate() {
            reg += pj * k.col(j).iter().zip(p).map(|(kij, pi)| kij * pi).sum::<f64>();
        }
        (0.5 * reg + 0.5 * r.iter().map(|v| v * v).sum::<f64>(), r, flow)
    };
    let (e0, residual, flow) = energy(&fit.momenta);
    let jac = position_jacobian(&cp, &flow, 2);
    // The dense solver's own step (its smallest damping that factors: the undamped one is singular here).
    let mut best = e0;
    for damping in [0.0, 1e-18, 1e-16, 1e-14] {
        let Some(f) = StepFactor::new(&jac, &k, o.sigma, damping, DampingScale::PerParameter, 1e-11, Par::rayon(2)) else { continue };
        let step = f.step(&k, &residual, &fit.momenta);
        if step.iter().all(|v| v.is_finite()) {
            let trial: Vec<f64> = fit.momenta.iter().zip(&step).map(|(a, b)| a + b).collect();
            best = best.min(energy(&trial).0);
        }
    }
    let gain = (e0 - best) / e0;
    eprintln!("eigenspace energy {e0:.7e}; best full-space Gauss–Newton step {best:.7e} (relative gain {gain:.2e})");
    assert!(gain < 1e-6, "a full-space Gauss–Newton step lowers the energy by {gain:e} (relative)");
}

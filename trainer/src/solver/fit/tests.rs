use super::problem::cancellation_of;
use super::search_space::choose_basis;
use super::*;
use crate::simulate::{configurations, rr, Sampling};
use crate::solver::regulariser::regulariser_matrix;
use faer::Mat;

fn rr_points(per_axis: usize) -> (ControlPoints, Measurements) {
    let data = rr::RealRr::default().measure(&configurations(Sampling::Grid { per_axis }, 2));
    let o = CbdOptions::paper_rr();
    let cp = ControlPoints::new(
        &rr::nominal(),
        &o.normalisation,
        data.joints.clone(),
        o.joint_kernel,
        o.task_kernel,
        o.solver.law,
        o.integrator,
    );
    (cp, data)
}

/// Momenta that nearly cancel: Σ|K P| / |Σ K P| is the amplification of rounding.
#[test]
fn cancellation_measures_how_much_the_momenta_cancel() {
    let k = Mat::from_fn(2, 2, |_, _| 1.0);
    assert_eq!(cancellation_of(&k, &[1.0, 2.0]), 1.0);
    let c = cancellation_of(&k, &[1e6, -1e6 + 1.0]);
    assert!((c - (2e6 - 1.0)).abs() < 1e-3, "{c}");
    assert_eq!(cancellation_of(&k, &[0.0, 0.0]), 1.0);
}

/// With every eigenvector kept (S square and orthogonal) the eigenspace method's steps are the
/// dense method's, rotated: same momenta after each Gauss–Newton step, to rounding.
#[test]
fn eigenspace_steps_match_dense_steps_when_nothing_is_cut() {
    let (cp, data) = rr_points(4);
    let k = regulariser_matrix(&cp);
    let e = choose_basis(SolverMethod::Eigenspace, &k).expect("eigenspace");
    assert_eq!(e.values.len(), k.nrows(), "the test needs the whole space (no eigenvalue below the cutoff)");
    for iterations in [1, 2] {
        let mut opts = CbdOptions::paper_rr();
        opts.sigma = 1e-3;
        opts.solver.max_iterations = iterations;
        opts.solver.method = SolverMethod::Dense;
        let dense = fit_cbd(&rr::nominal(), &data, &opts).unwrap();
        opts.solver.method = SolverMethod::Eigenspace;
        let sub = fit_cbd(&rr::nominal(), &data, &opts).unwrap();
        assert_eq!((dense.report.method.as_str(), sub.report.method.as_str()), ("dense", "eigenspace"));
        let scale = dense.momenta.iter().fold(0.0f64, |s, v| s.max(v.abs()));
        let worst = dense.momenta.iter().zip(&sub.momenta).fold(0.0f64, |w, (a, b)| w.max((a - b).abs()));
        assert!(worst < 1e-9 * scale, "{iterations} iterations: {worst:e} (scale {scale:e})");
    }
}

/// Auto: dense up to DENSE_MAX_UNKNOWNS unknowns; above, the eigenspace, whose size does not
/// grow with N on the RR benchmark (about 850 directions at N = 1024, see `solver::subspace`).
#[test]
fn automatic_choice_is_dense_for_small_and_eigenspace_for_large_problems() {
    let (small, _) = rr_points(16);
    assert!(small.len() * 2 <= DENSE_MAX_UNKNOWNS);
    assert!(choose_basis(SolverMethod::Auto, &regulariser_matrix(&small)).is_none());
    let (large, _) = rr_points(32);
    let e = choose_basis(SolverMethod::Auto, &regulariser_matrix(&large)).expect("eigenspace at N = 1024");
    let r = e.values.len();
    assert!((700..1000).contains(&r), "eigenspace dimension {r}");
    assert_eq!((e.basis.nrows(), e.basis.ncols()), (2048, r));
    assert!(choose_basis(SolverMethod::Dense, &regulariser_matrix(&large)).is_none());
}

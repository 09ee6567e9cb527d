//! Trainer → blob → runtime on a reduced RR benchmark (8 × 8 grid).

use cbd_runtime::Calibrator;
use cbd_trainer::report::stats::ErrorStats;
use cbd_trainer::simulate::{configurations, rr, Sampling};
use cbd_trainer::solver::{fit_cbd, CbdOptions};

fn small_fit(threads: usize) -> (cbd_trainer::solver::CbdFit, cbd_trainer::data::Measurements) {
    let train = rr::RealRr::default().measure(&configurations(Sampling::Grid { per_axis: 8 }, 2));
    let mut opts = CbdOptions::paper_rr();
    opts.solver.max_iterations = 8;
    opts.solver.threads = threads;
    (fit_cbd(&rr::nominal(), &train, &opts).expect("fit"), train)
}

#[test]
fn runtime_reproduces_the_trainer_and_generalises() {
    let (fit, train) = small_fit(2);
    let mut storage = vec![0.0; 100_000];
    let mut cal = Calibrator::load(&fit.blob, &mut storage).expect("load");
    let mut worst: f64 = 0.0;
    for i in 0..train.len() {
        let e = cal.evaluate(train.joints(i)).unwrap();
        for (a, b) in e.position().iter().zip(&fit.train_predictions[2 * i..2 * i + 2]) {
            worst = worst.max((a - b).abs() / b.abs().max(1.0));
        }
    }
    assert!(worst <= 1e-12, "runtime vs trainer at the training points: {worst:e}");
    assert!(fit.report.max_runtime_trainer_diff <= 1e-12);

    let test = rr::RealRr::default().measure(&configurations(Sampling::Uniform { count: 300, seed: 9 }, 2));
    let predicted = cbd_trainer::predict::evaluate_blob(&fit.blob, &test.joints).unwrap();
    let nominal: Vec<f64> = test
        .joints
        .chunks(2)
        .flat_map(|q| cbd_runtime::internals::kinematics::forward_kinematics(&rr::nominal(), q).position[..2].to_vec())
        .collect();
    let before = ErrorStats::of_positions(&nominal, &test.positions, 2);
    let after = ErrorStats::of_positions(&predicted, &test.positions, 2);
    // 64 measurements only: still at least three orders of magnitude on random configurations.
    assert!(after.mean < before.mean * 1e-3, "before {:e}, after {:e}", before.mean, after.mean);
}

#[test]
fn the_same_inputs_give_the_same_blob_with_one_or_two_threads() {
    let (a, _) = small_fit(1);
    let (b, _) = small_fit(2);
    assert_eq!(a.blob, b.blob);
}

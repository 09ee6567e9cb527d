//! On the simulated 6-joint arm (geometric errors + gravity joint compliance + 0.01 mm noise),
//! DH calibration followed by CbD generalises to fresh random configurations at the noise level.

use cbd_trainer::face::peers::cbd_correction as cbd_fitter;
use cbd_trainer::parametric::{calibrate_dh, DhCalibrationOptions};
use cbd_trainer::report::stats::ErrorStats;
use cbd_trainer::simulate::six_joint::{random_configurations, SixJointRobot};

#[test]
fn dh_plus_cbd_reaches_the_noise_level_on_fresh_configurations() {
    let robot = SixJointRobot::ur5_like(1);
    let train = robot.measure(&random_configurations(400, 11), 12);
    let test = robot.measure(&random_configurations(200, 13), 14);
    let dh = calibrate_dh(&robot.nominal, &train, &DhCalibrationOptions::default()).expect("DH calibration");
    let settings = cbd_trainer::calibrate::Settings { steps: Some(1), ..Default::default() };
    let fit = cbd_fitter(&settings);
    let predict = fit(&dh.model, &train).expect("CbD fit").predict;
    let stats = ErrorStats::of_positions(&predict(&test.joints), &test.positions, 3);
    // The measured positions themselves carry noise: E|ε| for a 3-D Gaussian with σ per
    // coordinate is 1.596 σ, the floor of any model's mean error against them.
    let noise_floor = 1.596 * robot.noise_std;
    eprintln!("dh+cbd mean test error {:.4} mm, noise floor {:.4} mm", stats.mean, noise_floor);
    assert!(stats.mean <= 2.0 * noise_floor, "mean {} mm vs noise floor {} mm", stats.mean, noise_floor);
}

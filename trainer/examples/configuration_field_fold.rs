//! The configuration-dependent task field on one train/test split (issue 49 item 3; docs/DESIGN.md
//! §16): `cbd fit`'s default pipeline on TRAIN, then the test mean error of the plain model (its blob,
//! evaluated by the runtime) and of the model with the term (the comparison's hyperparameters, fitted
//! in closed form and evaluated by the trainer's own kernels, which the runtime reproduces: a
//! reference independent of the blob), with both log evidences and the decision.
//!
//!     cargo run --release -p cbd-trainer --example configuration_field_fold -- MODEL.toml|- TRAIN.csv TEST.csv

use cbd_protocol::{Integrator, IntegratorMethod};
use cbd_trainer::calibrate::{calibrate, normalisation_for, options_for, Settings};
use cbd_trainer::data::csv_import::read_measurements;
use cbd_trainer::data::Measurements;

fn mean_error(predicted: &[f64], data: &Measurements) -> f64 {
    let m = data.task_dim;
    let rows = data.len();
    (0..rows).map(|i| (0..m).map(|c| (predicted[i * m + c] - data.positions[i * m + c]).powi(2)).sum::<f64>().sqrt()).sum::<f64>()
        / rows as f64
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let [_, model, train, test] = &args[..] else { panic!("usage: configuration_field_fold MODEL.toml TRAIN.csv TEST.csv") };
    // `-`: the paper's RR arm (CSV q1, q2, x, y), as `cbd` without --model.
    let model_args = cbd_trainer::cli::ModelArgs { model: (model != "-").then(|| model.into()) };
    let arm = cbd_trainer::cli::ArmModel::read(&model_args).unwrap_or_else(|e| panic!("{e}"));
    let (nominal, spec) = (arm.nominal, arm.spec);
    let train = read_measurements(train, &spec).unwrap_or_else(|e| panic!("{e}")).measurements;
    let test = read_measurements(test, &spec).unwrap_or_else(|e| panic!("{e}")).measurements;
    let mut settings = Settings::default();
    settings.solver.verbose = false;
    let t0 = std::time::Instant::now();
    let c = calibrate(&nominal, &train, &settings).unwrap_or_else(|e| panic!("{e}"));
    let seconds = t0.elapsed().as_secs_f64();
    let plain = cbd_trainer::predict::evaluate_blob(&c.fit.blob, &test.joints).unwrap_or_else(|e| panic!("{e}"));
    let plain_error = mean_error(&plain, &test);
    let Some(f) = &c.configuration else { panic!("no configuration search ran") };
    let norm = normalisation_for(&train.normalisation(), &settings);
    let opts = options_for(&f.with_term, &norm, Integrator { method: IntegratorMethod::Euler, steps: 1 }, &settings);
    let t1 = std::time::Instant::now();
    let momenta = cbd_trainer::solver::solve_with_configuration(&c.base, &train, &opts).unwrap_or_else(|e| panic!("{e}"));
    let with = cbd_trainer::solver::predict_with_configuration(&c.base, &opts, &train.joints, &momenta, &test.joints).unwrap();
    let fit_seconds = t1.elapsed().as_secs_f64();
    println!(
        "plain {plain_error:.4e} | with term {:.4e} | chosen {} | lml {:.1} → {:.1} (margin {:.1}) | pipeline {seconds:.1} s (term search {:.1} s), term fit+predict {fit_seconds:.1} s | {}",
        mean_error(&with, &test),
        f.chosen,
        f.plain_log_evidence,
        f.with_term_log_evidence,
        f.margin,
        f.seconds,
        c.geometry.describe()
    );
}

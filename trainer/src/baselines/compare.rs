//! Every peer on the same data: nominal, parametric DH calibration, kernel ridge / GP regression
//! of the residual (hyperparameters by marginal likelihood on the training rows only), the
//! hybrid DH + KRR, and — through a hook — Calibration by Diffeomorphisms and DH + CbD.

use super::krr::KernelRidge;
use crate::data::import_error::ImportError;
use crate::data::Measurements;
use crate::error::Error;
use crate::kernels::hyperparameters::{choose_hyperparameters, Hyperparameters, SearchOptions};
use crate::parametric::{calibrate_dh, DhCalibrationOptions, DhFitStats};
use crate::report::stats::ErrorStats;
use cbd_protocol::NominalModel;
use std::time::Instant;

/// Predicted positions (row-major, `task_dim` per row) at joint rows (row-major).
pub type Predictor = Box<dyn Fn(&[f64]) -> Vec<f64>>;

/// Fits a nonparametric correction on top of a nominal model and returns its predictor.
/// The hook through which CbD enters the comparison (see [`compare_peers`]).
/// A fitted correction and one line saying what was chosen (hyperparameters, scheme, warnings).
pub type FittedCorrection = (Predictor, String);
pub type CorrectionFitter<'a> = &'a dyn Fn(&NominalModel, &Measurements) -> crate::Result<FittedCorrection>;

/// One method's row.
#[derive(Debug, Clone, PartialEq)]
pub struct PeerResult {
    /// `nominal`, `dh`, `krr`, `dh+krr`, `cbd`, `dh+cbd`.
    pub name: String,
    /// Test-row errors (model length unit).
    pub stats: ErrorStats,
    /// Training-row errors.
    pub train_stats: ErrorStats,
    pub fit_seconds: f64,
    /// Position error of every test row (for plots).
    pub test_errors: Vec<f64>,
    /// Chosen hyperparameters, DH fit summary, or why the method failed.
    pub note: String,
}

/// Everything [`compare_peers`] found, besides the table.
#[derive(Debug, Clone)]
pub struct Comparison {
    pub rows: Vec<PeerResult>,
    pub dh: Option<DhFitStats>,
    pub krr_hyperparameters: Option<Hyperparameters>,
    pub dh_krr_hyperparameters: Option<Hyperparameters>,
}

impl Comparison {
    /// The `cbd compare --json` shape: `{"methods": {name: {mean, median, p99, max, fit_seconds,
    /// train_mean, note}}, "dh": {...}, "hyperparameters": {"krr": ..., "dh+krr": ...}}`.
    pub fn to_json(&self) -> serde_json::Value {
        use serde_json::json;
        let mut methods = serde_json::Map::new();
        for r in &self.rows {
            methods.insert(
                r.name.clone(),
                json!({
                    "mean": r.stats.mean, "median": r.stats.median, "p99": r.stats.p99, "max": r.stats.max,
                    "fit_seconds": r.fit_seconds, "train_mean": r.train_stats.mean, "note": r.note,
                }),
            );
        }
        let hyper = |h: &Option<Hyperparameters>| {
            h.as_ref().map(|h| {
                let widths: Vec<serde_json::Value> = h
                    .kernel
                    .axes
                    .iter()
                    .map(|a| match a {
                        cbd_protocol::JointKernelAxis::Periodic { b } => json!({ "periodic_b": b }),
                        cbd_protocol::JointKernelAxis::Gaussian { width } => json!({ "gaussian_width": width }),
                    })
                    .collect();
                json!({
                    "joint_axes": widths, "gamma": h.kernel.gamma, "noise_sigma": h.noise_sigma,
                    "noise_sigma_data_units": h.noise_sigma_data_units(), "task_scale": h.task_scale,
                    "log_marginal_likelihood": h.log_marginal_likelihood, "evaluations": h.evaluations, "rows_used": h.rows_used,
                })
            })
        };
        json!({
            "methods": methods,
            "dh": self.dh.as_ref().map(|d| json!({
                "iterations": d.iterations, "initial_rms": d.initial_rms, "final_rms": d.final_rms,
                "n_parameters": d.n_parameters, "rank": d.rank, "unidentifiable": d.unidentifiable,
                "redundant_at_nominal": d.redundant_at_nominal, "converged": d.converged,
            })),
            "hyperparameters": { "krr": hyper(&self.krr_hyperparameters), "dh+krr": hyper(&self.dh_krr_hyperparameters) },
            "warnings": self.warnings(),
        })
    }

    /// What the reader must not miss: a DH fit that stopped at its iteration limit.
    pub fn warnings(&self) -> Vec<String> {
        self.dh.iter().filter(|d| !d.converged).map(dh_not_converged).collect()
    }

    /// A plain-text table, one line per method. Errors in fixed point with four decimals, or — when
    /// any is below 0.01 of the unit (RR data in metres), where that would print 0.0000 — all of them
    /// with four significant digits.
    pub fn table(&self, unit: &str) -> String {
        let errors = self.rows.iter().flat_map(|r| [r.stats.mean, r.stats.median, r.stats.p99, r.stats.max]);
        let scientific = errors.filter(|v| *v != 0.0).any(|v| v.abs() < 0.01);
        let cell = |v: f64| if scientific { format!("{v:>10.3e}") } else { format!("{v:>10.4}") };
        let mut out = format!("{:<8} {:>10} {:>10} {:>10} {:>10} {:>10}  ({unit})\n", "method", "mean", "median", "p99", "max", "fit [s]");
        for r in &self.rows {
            out += &format!(
                "{:<8} {} {} {} {} {:>10.2}\n",
                r.name,
                cell(r.stats.mean),
                cell(r.stats.median),
                cell(r.stats.p99),
                cell(r.stats.max),
                r.fit_seconds
            );
        }
        out
    }
}

/// The warning for a DH fit that stopped at its iteration limit.
pub fn dh_not_converged(d: &DhFitStats) -> String {
    format!(
        "DH calibration stopped at its iteration limit ({} iterations) without converging: training RMS error {:.4e} (from {:.4e}); every model built on that chain (dh, dh+krr, dh+cbd) inherits it",
        d.iterations, d.final_rms, d.initial_rms
    )
}

/// [`compare_peers`] from files: the model file, and training and test CSVs read with the model
/// file's `[measurements]` columns. Returns the comparison and the import warnings.
pub fn compare_files(
    model_file: impl AsRef<std::path::Path>,
    train_csv: impl AsRef<std::path::Path>,
    test_csv: impl AsRef<std::path::Path>,
    search: &SearchOptions,
    cbd: Option<CorrectionFitter>,
) -> Result<(Comparison, Vec<String>), ImportError> {
    let inputs = read_compare_files(model_file, train_csv, test_csv)?;
    Ok((compare_peers(&inputs.nominal, &inputs.train.measurements, &inputs.test.measurements, search, cbd), inputs.warnings))
}

/// What `compare_files` reads: the model file's nominal model, both measurement files (with their
/// line numbers) and the import warnings.
pub struct CompareInputs {
    pub nominal: NominalModel,
    pub train: crate::data::csv_import::ImportedMeasurements,
    pub test: crate::data::csv_import::ImportedMeasurements,
    pub warnings: Vec<String>,
    /// The base registered on the training rows (`[chain] base = { register = true }`).
    pub registration: Option<crate::nominal::register::Registration>,
}

/// Reads a comparison's model file and measurement files (no fitting yet); an unknown base is
/// registered on the training rows.
pub fn read_compare_files(
    model_file: impl AsRef<std::path::Path>,
    train_csv: impl AsRef<std::path::Path>,
    test_csv: impl AsRef<std::path::Path>,
) -> Result<CompareInputs, ImportError> {
    use crate::data::csv_import::read_measurements;
    let model = crate::data::model_file::load_model_file(model_file)?;
    let spec = model.column_spec()?;
    let train = read_measurements(train_csv.as_ref(), &spec)?;
    let test = read_measurements(test_csv.as_ref(), &spec)?;
    let mut warnings = train.warnings(train_csv.as_ref());
    warnings.extend(test.warnings(test_csv.as_ref()));
    let mut nominal = model.nominal;
    let registration = match model.register_base {
        true => Some(crate::nominal::register::register_base(&mut nominal, &train.measurements).map_err(|e| ImportError::Csv {
            file: train_csv.as_ref().to_path_buf(),
            line: None,
            column: None,
            message: e.to_string(),
        })?),
        false => None,
    };
    Ok(CompareInputs { nominal, train, test, warnings, registration })
}

/// `model`'s first `m` task coordinates (`m` < its own for a planar arm's DH form).
fn nominal_predictor(model: NominalModel, m: usize) -> Predictor {
    Box::new(move |joints: &[f64]| crate::nominal::positions(&model, joints, m))
}

/// `fit` on `base` for data of `data.task_dim` coordinates. A planar arm's DH form (three) is
/// fitted as the planar chain it is in a moved frame (`nominal::planar::as_planar_in_frame`),
/// the data moved into that frame and the predictions back. (Lifting the data to 3-D instead
/// would hand the correction a noise-free coordinate, which drives its noise estimate to zero.)
pub fn fit_on(fit: CorrectionFitter, base: &NominalModel, data: &Measurements) -> crate::Result<FittedCorrection> {
    use crate::nominal::planar::as_planar_in_frame;
    let (m, full) = (data.task_dim, base.task_dim());
    if m == full {
        return fit(base, data);
    }
    if let (2, Some((chain, frame))) = (m, as_planar_in_frame(base)) {
        let mut moved = Measurements::new(data.n_joints, 2);
        let joints = frame.chain_joints(&data.joints);
        for i in 0..data.len() {
            moved.push(&joints[i * data.n_joints..(i + 1) * data.n_joints], &frame.to_chain(data.position(i)));
        }
        let (predict, note) = fit(&chain, &moved)?;
        let back: Predictor = Box::new(move |joints: &[f64]| {
            predict(&frame.chain_joints(joints)).chunks_exact(2).flat_map(|p| frame.from_chain(p)).collect()
        });
        return Ok((back, note));
    }
    Err(Error::InvalidInput(format!("a model of {full} task coordinates for data of {m} that is not a planar arm's DH form")))
}

fn krr_on(model: &NominalModel, train: &Measurements, search: &SearchOptions) -> crate::Result<(Predictor, Hyperparameters)> {
    let h = choose_hyperparameters(model, train, search)?;
    let krr = KernelRidge::fit(model, train, h.kernel.clone(), h.ridge())?;
    let model = model.clone();
    Ok((Box::new(move |joints: &[f64]| krr.predict(&model, joints)), h))
}

fn describe(h: &Hyperparameters) -> String {
    let widths: Vec<String> = h
        .kernel
        .axes
        .iter()
        .map(|a| match a {
            cbd_protocol::JointKernelAxis::Periodic { b } => format!("b={b:.3}"),
            cbd_protocol::JointKernelAxis::Gaussian { width } => format!("l={width:.3}"),
        })
        .collect();
    format!(
        "{} gamma={:.3e} sigma={:.3e} (normalised, scale {:.4}; sigma {:.4} in data units) lml={:.2} after {} evaluations on {} rows",
        widths.join(" "),
        h.kernel.gamma,
        h.noise_sigma,
        h.task_scale,
        h.noise_sigma_data_units(),
        h.log_marginal_likelihood,
        h.evaluations,
        h.rows_used
    )
}

/// Runs every peer: fits on `train` only, reports errors on `test`. `cbd` is the hook for
/// Calibration by Diffeomorphisms: when given, it is fitted on the nominal model (`cbd`) and on
/// the DH-calibrated model (`dh+cbd`); when `None`, those rows are absent.
pub fn compare_peers(
    nominal: &NominalModel,
    train: &Measurements,
    test: &Measurements,
    search: &SearchOptions,
    cbd: Option<CorrectionFitter>,
) -> Comparison {
    let m = nominal.task_dim();
    let mut rows = Vec::new();
    let mut push = |name: &str, fitted: crate::Result<(Predictor, String)>, seconds: f64| {
        let (stats, train_stats, note, test_errors) = match fitted {
            Ok((p, note)) => {
                let predicted = p(&test.joints);
                let test_errors = crate::report::plots::position_errors(&predicted, &test.positions, m);
                (ErrorStats::of_errors(&test_errors), ErrorStats::of_positions(&p(&train.joints), &train.positions, m), note, test_errors)
            }
            Err(e) => {
                let nan = ErrorStats::of_errors(&[]);
                (nan, nan, format!("failed: {e}"), Vec::new())
            }
        };
        rows.push(PeerResult { name: name.to_string(), stats, train_stats, fit_seconds: seconds, test_errors, note });
    };
    push("nominal", Ok((nominal_predictor(nominal.clone(), m), String::new())), 0.0);

    let t = Instant::now();
    let dh = calibrate_dh(nominal, train, &DhCalibrationOptions { planar_as_dh: true, ..DhCalibrationOptions::default() });
    let dh_seconds = t.elapsed().as_secs_f64();
    let dh_model = dh.as_ref().ok().map(|f| f.model.clone());
    push(
        "dh",
        dh.as_ref()
            .map(|f| {
                let s = &f.stats;
                (
                    nominal_predictor(f.model.clone(), m),
                    format!(
                        "{} iterations{}, rank {}/{}, train rms {:.4e}",
                        s.iterations,
                        if s.converged { "" } else { " (iteration limit: not converged)" },
                        s.rank,
                        s.n_parameters,
                        s.final_rms
                    ),
                )
            })
            .map_err(|e| Error::from(e.clone())),
        dh_seconds,
    );

    let t = Instant::now();
    let krr = krr_on(nominal, train, search);
    let krr_seconds = t.elapsed().as_secs_f64();
    let krr_h = krr.as_ref().ok().map(|(_, h)| h.clone());
    push("krr", krr.map(|(p, h)| (p, describe(&h))), krr_seconds);

    let mut dh_krr_h = None;
    if let Some(dh_model) = &dh_model {
        let t = Instant::now();
        let fitted = krr_on(dh_model, train, search);
        let seconds = dh_seconds + t.elapsed().as_secs_f64();
        dh_krr_h = fitted.as_ref().ok().map(|(_, h)| h.clone());
        push("dh+krr", fitted.map(|(p, h)| (p, describe(&h))), seconds);
    }

    // ---- Hook: Calibration by Diffeomorphisms (filled by the caller, e.g. with
    // `cbd_trainer::solver::fit_cbd` and `crate::predict::evaluate_blob`). ----
    if let Some(fit) = cbd {
        let t = Instant::now();
        let fitted = fit(nominal, train);
        push("cbd", fitted, t.elapsed().as_secs_f64());
        if let Some(dh_model) = &dh_model {
            let t = Instant::now();
            let fitted = fit_on(fit, dh_model, train);
            push("dh+cbd", fitted, dh_seconds + t.elapsed().as_secs_f64());
        }
    }

    Comparison { rows, dh: dh.ok().map(|f| f.stats), krr_hyperparameters: krr_h, dh_krr_hyperparameters: dh_krr_h }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::simulate::six_joint::{random_configurations, SixJointRobot};

    #[test]
    fn peers_on_the_simulated_six_joint_arm() {
        let robot = SixJointRobot::ur5_like(21);
        let train = robot.measure(&random_configurations(250, 22), 23);
        let test = robot.measure(&random_configurations(100, 24), 25);
        let search = SearchOptions { max_evaluations: 100, ..SearchOptions::default() };
        // A stand-in correction for the hook: KRR again, to check the plumbing.
        let hook = |model: &NominalModel, data: &Measurements| krr_on(model, data, &search).map(|(p, h)| (p, describe(&h)));
        let c = compare_peers(&robot.nominal, &train, &test, &search, Some(&hook));
        let names: Vec<&str> = c.rows.iter().map(|r| r.name.as_str()).collect();
        assert_eq!(names, ["nominal", "dh", "krr", "dh+krr", "cbd", "dh+cbd"]);
        let get = |n: &str| c.rows.iter().find(|r| r.name == n).unwrap().stats.mean;
        assert!(get("dh") < 0.2 * get("nominal"), "{:?}", c.rows);
        assert!(get("dh+krr") <= get("dh") * 1.05, "{:?}", c.rows);
        assert_eq!(get("dh+krr"), get("dh+cbd"));
        for r in &c.rows {
            eprintln!(
                "{:8} mean {:.4} median {:.4} p99 {:.4} max {:.4} fit {:.2}s  {}",
                r.name, r.stats.mean, r.stats.median, r.stats.p99, r.stats.max, r.fit_seconds, r.note
            );
        }
        let json = c.to_json();
        for name in ["nominal", "dh", "krr", "cbd", "dh+krr", "dh+cbd"] {
            for key in ["mean", "median", "p99", "max", "fit_seconds"] {
                assert!(json["methods"][name][key].is_number(), "{name}.{key}");
            }
        }
        assert!(c.table("mm").lines().count() == 7);
    }

    /// Issue 26: RR data in metres printed every good row as 0.0000; errors below 0.01 of the unit
    /// switch the whole table to four significant digits.
    #[test]
    fn small_errors_keep_their_digits_in_the_table() {
        let row = |name: &str, v: f64| PeerResult {
            name: name.into(),
            stats: ErrorStats { mean: v, median: v, p99: v, max: v },
            train_stats: ErrorStats { mean: v, median: v, p99: v, max: v },
            fit_seconds: 0.5,
            test_errors: vec![],
            note: String::new(),
        };
        let table = |rows| Comparison { rows, dh: None, krr_hyperparameters: None, dh_krr_hyperparameters: None }.table("m");
        let small = table(vec![row("nominal", 0.1083), row("cbd", 1.2916e-5)]);
        assert!(small.contains("1.292e-5") && small.contains("1.083e-1") && !small.contains("0.0000"), "{small}");
        let large = table(vec![row("nominal", 3.25), row("cbd", 0.0876)]);
        assert!(large.contains("3.2500") && large.contains("0.0876"), "{large}");
    }

    /// Issue 26: a DH fit at its iteration limit said only "200 iterations" in the text output.
    #[test]
    fn a_dh_fit_at_its_iteration_limit_is_a_warning() {
        let robot = SixJointRobot::ur5_like(21);
        let train = robot.measure(&random_configurations(60, 22), 23);
        let options = DhCalibrationOptions { max_iterations: 1, ..DhCalibrationOptions::default() };
        let stats = calibrate_dh(&robot.nominal, &train, &options).unwrap().stats;
        assert!(!stats.converged);
        let c = Comparison { rows: vec![], dh: Some(stats), krr_hyperparameters: None, dh_krr_hyperparameters: None };
        let w = c.warnings();
        assert!(w.len() == 1 && w[0].contains("iteration limit (1 iterations)"), "{w:?}");
        assert_eq!(c.to_json()["warnings"][0], serde_json::json!(w[0]));
    }

    /// Issue 14: a planar model gets DH calibration (base, joint offsets, lengths) and the hybrids.
    #[test]
    fn peers_on_a_planar_arm_with_base_and_joint_offsets() {
        use crate::simulate::effects::EffectArm;
        use crate::simulate::{configurations, rr::planar_arm, Sampling};
        let arm = EffectArm::new(planar_arm(&[1.03, 0.48], [0.03, -0.02], 0.01, &[0.01, -0.02]));
        let train = arm.measure_planar(&configurations(Sampling::Uniform { count: 120, seed: 1 }, 2), 1e-4, 2);
        let test = arm.measure_planar(&configurations(Sampling::Uniform { count: 100, seed: 3 }, 2), 1e-4, 4);
        let search = SearchOptions { max_evaluations: 60, ..SearchOptions::default() };
        let hook = |model: &NominalModel, data: &Measurements| krr_on(model, data, &search).map(|(p, h)| (p, describe(&h)));
        let nominal = NominalModel::planar(&[1.0, 0.5]).unwrap();
        let c = compare_peers(&nominal, &train, &test, &search, Some(&hook));
        let names: Vec<&str> = c.rows.iter().map(|r| r.name.as_str()).collect();
        assert_eq!(names, ["nominal", "dh", "krr", "dh+krr", "cbd", "dh+cbd"]);
        let get = |n: &str| c.rows.iter().find(|r| r.name == n).unwrap().stats.mean;
        // Geometry is all there is: DH calibration reaches the noise (E|ε| = 1.25e-4).
        assert!(get("dh") < 2e-4 && get("nominal") > 100.0 * get("dh"), "{:?}", c.rows);
        for name in ["dh+krr", "dh+cbd"] {
            assert!(get(name) < 1.2 * get("dh"), "{name}: {:?}", c.rows);
        }
    }
}

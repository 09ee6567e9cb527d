//! Every method on the same data: nominal, parametric DH calibration, and — from the list of
//! [`Peer`]s the caller gives (`face::peers`: the kernel-ridge peer of the residual, Calibration by
//! Diffeomorphisms) — each peer on the nominal model and on the DH-calibrated chain (`dh+<name>`).

use super::correction::{FittedCorrection, Predictor};
use super::peers::Peer;
use super::pose_errors::PoseErrors;
use crate::calibrate::dh_not_converged;
use crate::calibrate::{Geometry, GeometryChoice};
use crate::data::import_error::ImportError;
use crate::data::Measurements;
use crate::error::Error;
use crate::parametric::{calibrate_dh, DhCalibrationOptions, DhFitStats};
use crate::report::noise_floor::NoiseFloor;
use crate::report::stats::ErrorStats;
use cbd_protocol::NominalModel;
use std::time::Instant;

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
    /// The chosen hyperparameters for the JSON (the kernel-ridge rows).
    pub hyperparameters: Option<serde_json::Value>,
    /// With several tool points per pose: test errors per point and of the tool frame.
    pub pose: Option<PoseErrors>,
    /// The noise σ the method's own evidence estimated (CbD's rows), data unit.
    pub noise_sigma: Option<f64>,
}

/// Everything [`compare_peers`] found, besides the table.
#[derive(Debug, Clone, Default)]
pub struct Comparison {
    pub rows: Vec<PeerResult>,
    pub dh: Option<DhFitStats>,
    /// What `cbd fit` would choose on the training rows (its geometry), when asked: marks `cbd` or
    /// `dh+cbd` as the row it writes.
    pub default_fit: Option<GeometryChoice>,
    /// The noise floor of the test rows, from the σ CbD's evidence estimated on the training rows.
    pub noise_floor: Option<NoiseFloor>,
    /// The rows whose hyperparameters the JSON lists (null when a row failed or is missing): the
    /// rows of the peers with [`Peer::hyperparameters_in_json`].
    pub hyperparameter_rows: Vec<String>,
}

impl Comparison {
    /// The `cbd compare --json` shape: `{"methods": {name: {mean, median, p99, max, fit_seconds,
    /// train_mean, note}}, "dh": {...}, "hyperparameters": {"krr": ..., "dh+krr": ...}}`.
    pub fn to_json(&self) -> serde_json::Value {
        use serde_json::json;
        let mut methods = serde_json::Map::new();
        for r in &self.rows {
            let mut method = json!({
                "mean": r.stats.mean, "median": r.stats.median, "p99": r.stats.p99, "max": r.stats.max,
                "fit_seconds": r.fit_seconds, "train_mean": r.train_stats.mean, "note": r.note,
            });
            if let Some(pose) = &r.pose {
                method["pose"] = pose.to_json();
            }
            if let Some(floor) = &self.noise_floor {
                floor.verdict(r.stats.mean, r.test_errors.len()).write_json(&mut method);
            }
            if !r.stats.mean.is_finite() {
                method["failed"] = json!(true);
            }
            if self.written_by_fit() == Some(r.name.as_str()) {
                method["written_by_fit"] = json!(true);
            }
            methods.insert(r.name.clone(), method);
        }
        let hyper = |name: &str| self.rows.iter().find(|r| r.name == name).and_then(|r| r.hyperparameters.clone());
        let hyperparameters: serde_json::Map<String, serde_json::Value> =
            self.hyperparameter_rows.iter().map(|name| (name.clone(), json!(hyper(name)))).collect();
        json!({
            "methods": methods,
            "dh": self.dh.as_ref().map(|d| json!({
                "iterations": d.iterations, "initial_rms": d.initial_rms, "final_rms": d.final_rms,
                "n_parameters": d.n_parameters, "rank": d.rank, "unidentifiable": d.unidentifiable,
                "redundant_at_nominal": d.redundant_at_nominal, "converged": d.converged,
            })),
            "hyperparameters": hyperparameters,
            "default_fit": self.default_fit.as_ref().map(|g| json!({"method": self.written_by_fit(), "geometry": g})),
            "noise_floor": self.noise_floor,
            "warnings": self.warnings(),
        })
    }

    /// The row `cbd fit` writes with its default geometry (`cbd` or `dh+cbd`), when known.
    pub fn written_by_fit(&self) -> Option<&'static str> {
        self.default_fit.as_ref().map(|g| if g.chosen == Geometry::Calibrated { "dh+cbd" } else { "cbd" })
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
        // A failed method's figures are not numbers: said so, with no verdict beside them.
        let cell = |v: f64| {
            if !v.is_finite() {
                format!("{:>10}", "failed")
            } else if scientific {
                format!("{v:>10.3e}")
            } else {
                format!("{v:>10.4}")
            }
        };
        let floor_header = if self.noise_floor.is_some() { format!(" {:>8}", "/ floor") } else { String::new() };
        let mut out = format!(
            "{:<8} {:>10} {:>10} {:>10} {:>10} {:>10}{floor_header}  ({unit})\n",
            "method", "mean", "median", "p99", "max", "fit [s]"
        );
        let written = self.written_by_fit();
        for r in &self.rows {
            let floor =
                self.noise_floor.as_ref().map_or(String::new(), |f| format!(" {:>8}", f.verdict(r.stats.mean, r.test_errors.len()).cell()));
            let name = if written == Some(r.name.as_str()) { format!("{}*", r.name) } else { r.name.clone() };
            out += &format!(
                "{:<8} {} {} {} {} {:>10.2}{floor}\n",
                name,
                cell(r.stats.mean),
                cell(r.stats.median),
                cell(r.stats.p99),
                cell(r.stats.max),
                r.fit_seconds
            );
        }
        if let (Some(g), Some(row)) = (&self.default_fit, written) {
            out += &format!("* what `cbd fit` writes by default ({row}): {}\n", g.describe());
        }
        if let Some(f) = &self.noise_floor {
            out += &format!(
                "{}; `=` at it (more data or effects will not help), `>` above it (structure left: try `cbd diagnose`)\n",
                f.describe(unit)
            );
        }
        out += &self.pose_table(unit);
        out
    }

    /// With several tool points per pose: each method's mean error per tool point, of the tool
    /// frame's origin and of its orientation; empty otherwise.
    pub fn pose_table(&self, unit: &str) -> String {
        use super::pose_errors::{pose_table, PoseTableLayout};
        let rows: Vec<_> = self.rows.iter().map(|r| (r.name.as_str(), r.pose.as_ref())).collect();
        let heading = format!("mean test error per tool point and of the tool frame ({unit}; orientation in degrees)");
        pose_table(&heading, "method", &PoseTableLayout { indent: "", name_width: 8, number_width: 10 }, &rows)
    }
}

/// [`compare_peers`] from files: the model file, and training and test CSVs read with the model
/// file's `[measurements]` columns. Returns the comparison and the import warnings.
pub fn compare_files(
    model_file: impl AsRef<std::path::Path>,
    train_csv: impl AsRef<std::path::Path>,
    test_csv: impl AsRef<std::path::Path>,
    peers: &[Peer<'_>],
) -> Result<(Comparison, Vec<String>), ImportError> {
    let path = model_file.as_ref();
    let inputs = read_compare_files(&crate::data::model_file::load_model_file(path)?, train_csv, test_csv)?;
    Ok((compare_peers(&inputs.nominal, &inputs.train.measurements, &inputs.test.measurements, peers), inputs.warnings))
}

/// What `compare_files` reads: the model file's nominal model, both measurement files (with their
/// line numbers) and the import warnings.
pub struct CompareInputs {
    pub nominal: NominalModel,
    pub train: crate::data::csv_import::ImportedMeasurements,
    pub test: crate::data::csv_import::ImportedMeasurements,
    pub warnings: Vec<String>,
    /// The base registered on the training rows (`[chain] base = { register = true }`).
    pub registration: Option<crate::parametric::base_registration::Registration>,
}

/// Reads a comparison's measurement files with `model`'s columns (no fitting yet); an unknown base
/// is registered on the training rows.
pub fn read_compare_files(
    model: &crate::data::model_file::ModelFile,
    train_csv: impl AsRef<std::path::Path>,
    test_csv: impl AsRef<std::path::Path>,
) -> Result<CompareInputs, ImportError> {
    use crate::data::csv_import::read_measurements;
    let spec = model.column_spec()?;
    let train = read_measurements(train_csv.as_ref(), &spec)?;
    let test = read_measurements(test_csv.as_ref(), &spec)?;
    compare_inputs(model, (train_csv.as_ref(), train), (test_csv.as_ref(), test))
}

/// A comparison's measurements, read with `model`'s columns and each named as in messages (a
/// file's path, or what arrays are called): their warnings, and an unknown base registered on the
/// training rows.
pub fn compare_inputs(
    model: &crate::data::model_file::ModelFile,
    (train_name, train): (&std::path::Path, crate::data::csv_import::ImportedMeasurements),
    (test_name, test): (&std::path::Path, crate::data::csv_import::ImportedMeasurements),
) -> Result<CompareInputs, ImportError> {
    let mut warnings = train.warnings(train_name);
    warnings.extend(test.warnings(test_name));
    let mut nominal = model.nominal.clone();
    let registration =
        match model.register_base {
            true => Some(
                crate::parametric::base_registration::register_and_refine(&mut nominal, &train.measurements)
                    .map_err(|e| ImportError::Csv { file: train_name.to_path_buf(), line: None, column: None, message: e.to_string() })?,
            ),
            false => None,
        };
    Ok(CompareInputs { nominal, train, test, warnings, registration })
}

/// `model`'s first `m` task coordinates (`m` < its own for a planar arm's DH form).
fn nominal_predictor(model: NominalModel, m: usize) -> Predictor {
    Box::new(move |joints: &[f64]| crate::nominal::positions(&model, joints, m))
}

/// Runs every method: fits on `train` only, reports errors on `test`. The rows: `nominal`, `dh`,
/// then each of `peers` in order, fitted on the nominal model (its name) and, when it is
/// [`Peer::on_dh`], on the DH-calibrated chain (`dh+<name>`; [`Peer::fit_on_chain`]).
pub fn compare_peers(nominal: &NominalModel, train: &Measurements, test: &Measurements, peers: &[Peer<'_>]) -> Comparison {
    let m = nominal.task_dim();
    let mut rows = Vec::new();
    let mut push = |name: &str, fitted: crate::Result<FittedCorrection>, seconds: f64| {
        let (stats, train_stats, note, test_errors, hyperparameters, pose, noise_sigma) = match fitted {
            Ok(FittedCorrection { predict: p, note, hyperparameters, noise_sigma }) => {
                let predicted = p(&test.joints);
                let test_errors = crate::report::plots::position_errors(&predicted, &test.positions, m);
                let train_stats = ErrorStats::of_positions(&p(&train.joints), &train.positions, m);
                let pose = PoseErrors::of(nominal.tool_points(), &predicted, &test.positions, m);
                (ErrorStats::of_errors(&test_errors), train_stats, note, test_errors, hyperparameters, pose, noise_sigma)
            }
            Err(e) => {
                let nan = ErrorStats::of_errors(&[]);
                (nan, nan, format!("failed: {e}"), Vec::new(), None, None, None)
            }
        };
        rows.push(PeerResult {
            name: name.to_string(),
            stats,
            train_stats,
            fit_seconds: seconds,
            test_errors,
            note,
            hyperparameters,
            pose,
            noise_sigma,
        });
    };
    push("nominal", Ok(FittedCorrection::new(nominal_predictor(nominal.clone(), m), String::new())), 0.0);

    let t = Instant::now();
    let dh = calibrate_dh(nominal, train, &DhCalibrationOptions { planar_as_dh: true, ..DhCalibrationOptions::default() });
    let dh_seconds = t.elapsed().as_secs_f64();
    let dh_model = dh.as_ref().ok().map(|f| f.model.clone());
    push(
        "dh",
        dh.as_ref()
            .map(|f| {
                let s = &f.stats;
                FittedCorrection::new(
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

    for peer in peers {
        let t = Instant::now();
        let fitted = peer.fit_on_nominal(nominal, train);
        push(peer.name, fitted, t.elapsed().as_secs_f64());
        if let (true, Some(dh_model)) = (peer.on_dh, &dh_model) {
            let t = Instant::now();
            let fitted = peer.fit_on_chain(dh_model, train);
            push(&peer.dh_name(), fitted, dh_seconds + t.elapsed().as_secs_f64());
        }
    }
    let hyperparameter_rows = peers
        .iter()
        .filter(|p| p.hyperparameters_in_json)
        .flat_map(|p| std::iter::once(p.name.to_string()).chain(p.on_dh.then(|| p.dh_name())))
        .collect();

    Comparison { rows, dh: dh.ok().map(|f| f.stats), default_fit: None, noise_floor: None, hyperparameter_rows }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::simulate::six_joint::{random_configurations, SixJointRobot};

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
            hyperparameters: None,
            pose: None,
            noise_sigma: None,
        };
        let table = |rows| Comparison { rows, ..Comparison::default() }.table("m");
        let small = table(vec![row("nominal", 0.1083), row("cbd", 1.2916e-5)]);
        assert!(small.contains("1.292e-5") && small.contains("1.083e-1") && !small.contains("0.0000"), "{small}");
        let large = table(vec![row("nominal", 3.25), row("cbd", 0.0876)]);
        assert!(large.contains("3.2500") && large.contains("0.0876"), "{large}");
        // Issue 51 class 4: a method that failed (NaN figures) shows as failed, with no verdict,
        // in the table and the JSON.
        let floor = crate::report::noise_floor::NoiseFloor::new(0.01, 3, "test");
        let c = Comparison { rows: vec![row("nominal", 3.25), row("krr", f64::NAN)], noise_floor: Some(floor), ..Comparison::default() };
        let text = c.table("m");
        let failed = text.lines().find(|l| l.starts_with("krr")).unwrap();
        assert!(failed.contains("failed") && !failed.contains("NaN") && !failed.contains('>') && !failed.contains('='), "{text}");
        let json = c.to_json();
        assert_eq!(json["methods"]["krr"]["failed"], true);
        assert!(json["methods"]["krr"]["at_floor"].is_null() && json["methods"]["nominal"]["at_floor"] == false, "{json}");
    }

    /// Issue 26: a DH fit at its iteration limit said only "200 iterations" in the text output.
    #[test]
    fn a_dh_fit_at_its_iteration_limit_is_a_warning() {
        let robot = SixJointRobot::ur5_like(21);
        let train = robot.measure(&random_configurations(60, 22), 23);
        let options = DhCalibrationOptions { max_iterations: 1, ..DhCalibrationOptions::default() };
        let stats = calibrate_dh(&robot.nominal, &train, &options).unwrap().stats;
        assert!(!stats.converged);
        let c = Comparison { dh: Some(stats), ..Comparison::default() };
        let w = c.warnings();
        assert!(w.len() == 1 && w[0].contains("iteration limit (1 iterations)"), "{w:?}");
        assert_eq!(c.to_json()["warnings"][0], serde_json::json!(w[0]));
    }
}

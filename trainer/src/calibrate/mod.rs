//! "Calibrate this data": the one pipeline `fit`, `compare`, `diagnose`, `bench` and `demo` call.
//!
//! 1. The starting model and hyperparameters together ([`geometry`]): the nominal chain, or its
//!    geometric group calibrated first — as given, or (the default) whichever CbD's own evidence on
//!    the training rows scores higher ([`crate::evidence`]); the paper's RR values for the demo's
//!    reproduction. A hand-given value replaces that one hyperparameter after the search (so
//!    `--sigma S`, S the chosen value as printed, gives the default blob back).
//! 3. The scheme (Euler × 1 = the linearised model, Euler × 2): k-fold cross-validation on the
//!    training rows ([`scheme`]) unless given.
//! 4. The fit of the discrete flow, and a warning when it stalls.
//! 5. When asked, the drift test in measurement order ([`drift_test`]) on the DH-calibrated chain
//!    — the chain CbD deforms, or where the nominal was kept the chain the geometry choice fitted (a
//!    nominal chain's error of millimetres leaves second-order shape the test's joint kernel must
//!    carry, and the UR5 rows' drift went unseen there) — beside the field's search (it needs only
//!    the chain and the window of rows `data::stage_rows` cut for it).
//!
//! Every length a user gives or reads here is in the data's unit.

pub mod configuration;
pub mod drift_test;
pub mod geometry;
pub mod hyperparameters;
pub mod scheme;
pub mod settings;

pub use geometry::{Geometry, GeometryChoice};
pub use hyperparameters::{normalisation_for, options_for, paper_rr_hyperparameters};
pub use settings::{ConfigurationField, HyperparameterSource, Overrides, Settings};

use crate::data::stage_rows::StageRows;
use crate::data::Measurements;
use crate::evidence::{CbdHyperparameters, Evidence};
use crate::parametric::DhFitStats;
use crate::report::noise_floor::{FloorVerdict, NoiseFloor};
use crate::solver::{fit_cbd, CbdFit, CbdOptions};
use cbd_protocol::{NominalModel, Normalisation};

/// A calibrated model and how it was chosen.
#[derive(Debug, Clone)]
pub struct Calibration {
    /// The model CbD deforms: the nominal one, or the DH-calibrated chain.
    pub base: NominalModel,
    pub dh: Option<DhFitStats>,
    pub hyperparameters: CbdHyperparameters,
    /// The evidence search, when it ran.
    pub evidence: Option<Evidence>,
    /// Nominal or calibrated geometry, and what decided it.
    pub geometry: GeometryChoice,
    /// The configuration field's comparison, when its search ran (docs/DESIGN.md §16).
    pub configuration: Option<crate::evidence::ConfigurationEvidence>,
    pub scheme: scheme::SchemeChoice,
    pub options: CbdOptions,
    pub fit: CbdFit,
    /// Stalled fits and the like: printed by the CLI, in the JSON.
    pub warnings: Vec<String>,
    /// The drift test in measurement order, when asked for and the rows allow it ([`drift_test`]).
    pub drift: Option<drift_test::Drift>,
}

/// Calibrates `nominal` on `data` (training rows only).
pub fn calibrate(nominal: &NominalModel, data: &Measurements, settings: &Settings) -> crate::Result<Calibration> {
    calibrate_rows(nominal, &StageRows::new(data.clone(), &settings.cuts()), settings)
}

/// Calibrates `nominal` on `data`, the training rows with the cuts its stages take
/// (`settings.cuts()`: `StageRows::new`): each stage takes its pieces, none cuts the rows again.
pub fn calibrate_rows(nominal: &NominalModel, data: &StageRows, settings: &Settings) -> crate::Result<Calibration> {
    debug_assert!(data.folds.as_ref().map_or(true, |f| f.len() == settings.cuts().folds), "the rows were cut for other settings");
    // The evidence needs three rows (a covariance and something to predict), the fit two.
    let needed = if settings.searches_evidence(nominal) { 3 } else { 2 };
    if data.len() < needed {
        return Err(crate::solver::FitError::TooFewMeasurements { got: data.len(), needed }.into());
    }
    if settings.searches_evidence(nominal) {
        if let Some(why) = exact_nominal(nominal, &data.rows) {
            return Err(crate::Error::InvalidInput(why));
        }
    }
    let norm = normalisation_for(&data.normalisation, settings);
    // The DH-calibrated chain is fitted by the geometry stage, for the drift test too when it runs.
    let with_chain = settings.drift.is_some() && data.drift.is_some();
    let (chosen, geometry, fitted_chain) = geometry::choose_geometry(nominal, data, &norm, settings, with_chain)?;
    let geometry::Hypothesis { base, dh, hyperparameters, evidence, .. } = chosen;
    // The geometry is decided with the plain prior; the configuration field is then searched on the
    // chosen base's residual (the final hypothesis' rows) and kept by its own comparison.
    // The drift test needs only the chain: it runs beside the field's search (each search's starts
    // share the command's workers; the same bits in either order), not after the fit.
    let (configuration, drift) = rayon::join(
        || configuration::choose(&base, data, &norm, settings, &hyperparameters, evidence.is_some()),
        // No window: the rows have no time of measurement (declared unordered).
        || match (settings.drift.as_ref(), fitted_chain, data.drift.as_ref()) {
            (Some(options), Some(chain), Some(tested)) => drift_test::drift_of_chain(&chain, tested, options),
            _ => None,
        },
    );
    let mut configuration = configuration?;
    let with_term = configuration.clone().filter(|c| c.chosen || settings.configuration == ConfigurationField::On);
    let mut early_warnings = Vec::new();
    let (hyperparameters, scheme, options, fit) = match with_term {
        Some(c) if settings.configuration == ConfigurationField::Auto => {
            // The term has no expansion in format 8: where the plain model's fields are written in
            // the kernels' own basis (their kernel form cancels, so f32 controllers would lose every
            // digit: the RR demo's 1 : 3e10), or where the term's kernel form cancels beyond what
            // the runtime reproduces (1e-12), `auto` keeps the plain model and says why.
            let plain = plain_fit(&base, data, &hyperparameters, &norm, settings)?;
            let h = settings.overrides.apply(&base, c.with_term.clone());
            // Why not, and whether `on` may still fit it (not where it was tried and cancelled).
            let with = if configuration::needs_expansion(&plain.3) {
                Err(("the plain model's fields need the kernels' own basis, which the field lacks".to_string(), true))
            } else {
                match configuration::fit(&base, &data.rows, &h, &norm, settings) {
                    Ok(fitted) => Ok(fitted),
                    Err(e) if is_runtime_mismatch(&e) => {
                        Err((format!("its kernel form cancels beyond what the runtime reproduces ({e})"), false))
                    }
                    Err(e) => return Err(e),
                }
            };
            match with {
                Ok((scheme, options, fit)) => (h, scheme, options, fit),
                Err((why, on_may_fit)) => {
                    let advice = if on_may_fit {
                        "; --configuration-field on tries it in the kernel form (refused where that form cancels beyond what the runtime reproduces)"
                    } else {
                        ""
                    };
                    early_warnings.push(format!(
                        "the configuration field was chosen by evidence (+{:.1} nats) but is not used: {why}{advice}",
                        c.with_term_log_evidence - c.plain_log_evidence
                    ));
                    if let Some(c) = configuration.as_mut() {
                        c.not_used = Some(why);
                    }
                    plain
                }
            }
        }
        Some(c) => {
            let h = settings.overrides.apply(&base, c.with_term.clone());
            let (scheme, options, fit) = match configuration::fit(&base, &data.rows, &h, &norm, settings) {
                // Not the runtime's fault: the field's kernel form cancels on these rows (σ far below the kernels).
                Err(e) if is_runtime_mismatch(&e) => {
                    return Err(crate::Error::InvalidInput(format!(
                        "--configuration-field on: the field's kernel form cancels on these rows beyond what the runtime \
                         reproduces ({e}), so no blob can carry it; --configuration-field auto keeps the plain model here"
                    )))
                }
                fitted => fitted?,
            };
            (h, scheme, options, fit)
        }
        None => plain_fit(&base, data, &hyperparameters, &norm, settings)?,
    };
    let mut warnings = stall_warnings(&fit, &hyperparameters, data.rows.task_dim, settings.solver.max_iterations);
    warnings.splice(0..0, early_warnings);
    if let Some(d) = dh.as_ref().filter(|d| !d.converged) {
        warnings.insert(0, dh_not_converged(d));
    }
    Ok(Calibration { base, dh, hyperparameters, evidence, geometry, configuration, scheme, options, fit, warnings, drift })
}

/// The model without the configuration field: the scheme by cross-validation, then the fit.
fn plain_fit(
    base: &NominalModel,
    data: &StageRows,
    h: &CbdHyperparameters,
    norm: &Normalisation,
    settings: &Settings,
) -> crate::Result<(CbdHyperparameters, scheme::SchemeChoice, CbdOptions, CbdFit)> {
    let h = CbdHyperparameters { configuration: None, ..h.clone() };
    let scheme = scheme::choose_scheme(base, data, &h, norm, settings)?;
    let options = options_for(&h, norm, scheme.integrator, settings);
    let fit = fit_cbd(base, &data.rows, &options)?;
    Ok((h, scheme, options, fit))
}

/// The warning for a DH fit that stopped at its iteration limit.
pub fn dh_not_converged(d: &DhFitStats) -> String {
    format!(
        "DH calibration stopped at its iteration limit ({} iterations) without converging: training RMS error {:.4e} (from {:.4e}); every model built on that chain (dh, dh+krr, dh+cbd) inherits it",
        d.iterations, d.final_rms, d.initial_rms
    )
}

/// A fit that stops at the iteration limit, or far above the noise it was told about, is a warning
/// with its figures, never a silent result.
fn stall_warnings(fit: &CbdFit, h: &CbdHyperparameters, task_dim: usize, max_iterations: usize) -> Vec<String> {
    let r = &fit.report;
    let train_rms = r.log.last().map_or(f64::NAN, |l| l.train_rms);
    // The RMS of a position error (all coordinates) at the noise level is √m σ.
    let expected = (task_dim as f64).sqrt() * h.sigma;
    let mut out = Vec::new();
    if !r.converged && r.iterations >= max_iterations {
        out.push(format!(
            "the fit stopped at the iteration limit ({max_iterations}) with training RMS error {train_rms:.3e} (noise level √m σ = {expected:.3e}); raise --max-iterations or check the hyperparameters"
        ));
    }
    if r.cancellation > 1e5 {
        // The measure of what the runtime evaluates: the expansion's terms when the blob has one.
        let what = if r.expansion.is_some() { "the expansion's terms" } else { "the momenta" };
        out.push(format!(
            "{what} cancel to 1 part in {:.1e} (nearly singular kernels): evaluate this model in f64: the runtime's f32 feature (about 7 significant digits) would lose about {:.0} digits to it",
            r.cancellation,
            r.cancellation.log10()
        ));
    }
    if !(train_rms <= 10.0 * expected) {
        out.push(format!(
            "the fit stalled: training RMS error {train_rms:.3e} is over 10 × the noise level √m σ = {expected:.3e} the hyperparameters assume"
        ));
    }
    out
}

impl Calibration {
    /// The noise floor σ implies for the data's dimension (σ of the chosen hypothesis' evidence, or
    /// as given), and the held-out error of the chosen scheme's cross-validation against it.
    pub fn noise_floor(&self) -> (NoiseFloor, Option<FloorVerdict>) {
        let task_dim = self.base.task_dim();
        // Every training row is held out once by the cross-validation.
        let rows = self.fit.train_predictions.len() / task_dim.max(1);
        let source = match &self.evidence {
            Some(_) if self.hyperparameters.sigma == self.evidence.as_ref().map_or(f64::NAN, |e| e.hyperparameters.sigma) => {
                "CbD's evidence on the training rows"
            }
            _ => "the σ the fit used",
        };
        let floor = NoiseFloor::new(self.hyperparameters.sigma, task_dim, source);
        let held_out = self.scheme.cross_validation.iter().find(|(i, _)| *i == self.scheme.integrator).map(|&(_, rms)| rms);
        let verdict = held_out.map(|rms| floor.verdict_rms(rms, rows));
        (floor, verdict)
    }

    /// One line of the chosen hyperparameters, in the data's unit, each printed so that passing it
    /// back by hand reproduces it exactly (shortest round-trip form).
    pub fn describe_hyperparameters(&self) -> String {
        describe(&self.hyperparameters)
    }

    pub fn to_json(&self) -> serde_json::Value {
        let (floor, held_out) = self.noise_floor();
        serde_json::json!({
            "noise_floor": { "floor": floor, "held_out": held_out },
            "hyperparameters": self.hyperparameters,
            "evidence": self.evidence,
            "geometry": self.geometry,
            "configuration_field": self.configuration,
            "scheme": self.scheme.to_json(),
            "dh_first": self.dh.is_some(),
            "fit": self.fit.report,
            "warnings": self.warnings,
        })
    }
}

/// Relative residual (RMS residual over the positions' RMS spread) at or below which rows are the
/// nominal model's own positions: f64 forward kinematics agree to ~1e-15 of the reach; a tracker
/// resolves ~1e-6 of it.
pub const EXACT_NOMINAL: f64 = 1e-11;

/// Why `data` leaves CbD's evidence nothing to estimate, or `None`: its positions are the nominal
/// model's own (computed from the joints, or simulated with no error and no noise). The residual
/// is zero, so no σ has a positive-definite covariance behind it ("no start gave a
/// positive-definite covariance", or "the flow diverged … σ too small", with no word of the cause).
/// The caller names the file.
pub fn exact_nominal(nominal: &NominalModel, data: &Measurements) -> Option<String> {
    let m = data.task_dim;
    let predicted = crate::nominal::positions(nominal, &data.joints, m);
    let count = data.len().max(1) as f64;
    let rms = (predicted.iter().zip(&data.positions).map(|(a, b)| (a - b).powi(2)).sum::<f64>() / count).sqrt();
    let mean: Vec<f64> = (0..m).map(|c| data.positions.iter().skip(c).step_by(m).sum::<f64>() / count).collect();
    let spread = (data.positions.iter().enumerate().map(|(i, y)| (y - mean[i % m]).powi(2)).sum::<f64>() / count).sqrt();
    (rms <= EXACT_NOMINAL * spread.max(f64::MIN_POSITIVE) && rms.is_finite()).then(|| {
        format!(
            "the positions are the nominal model's own (RMS residual {} against a spread of {}): no error to calibrate and no noise for CbD's evidence to estimate σ from — measured positions are needed",
            crate::error::number(rms),
            crate::error::number(spread)
        )
    })
}

/// `v` shortest round-trip (passed back, the same value), in exponent form outside [1e-3, 1e7):
/// σ = 2.5942570536546676e-8, not 0.000000025942570536546676.
pub fn readable(v: f64) -> String {
    if v == 0.0 || !v.is_finite() || (1e-3..1e7).contains(&v.abs()) {
        format!("{v}")
    } else {
        format!("{v:e}")
    }
}

/// `--joint-b`/`--joint-widths`, `--gamma`, `--task-width`, `--task-gamma`, `--sigma` as one line.
pub fn describe(h: &CbdHyperparameters) -> String {
    let axes: Vec<String> = h
        .joint_axes
        .iter()
        .map(|a| {
            let (form, p) = crate::axis_forms::form_and_parameter(a);
            format!("{}={}", form.label(), readable(p))
        })
        .collect();
    let configuration = match &h.configuration {
        Some(c) => {
            let axes: Vec<String> = c
                .joint_axes
                .iter()
                .map(|a| format!("{}={}", crate::axis_forms::form_of(a).label(), readable(crate::axis_forms::form_and_parameter(a).1)))
                .collect();
            let width = c.task_width.map_or("flat".to_string(), readable);
            format!("; configuration field [{}] task width {width} gamma {}", axes.join(" "), readable(c.gamma))
        }
        None => String::new(),
    };
    format!(
        "joint kernel [{}] gamma {}; task kernel width {} gamma {}; sigma {}{configuration}",
        axes.join(" "),
        readable(h.joint_gamma),
        readable(h.task_width),
        readable(h.task_gamma),
        readable(h.sigma)
    )
}

/// The fit's blob evaluated by the runtime differs from the fit beyond 1e-12 (the kernel form cancels).
fn is_runtime_mismatch(e: &crate::Error) -> bool {
    matches!(e.stage_error(), Some(crate::solver::FitError::RuntimeMismatch(_)))
}

#[cfg(test)]
mod readable_tests {
    use super::*;

    #[test]
    fn hyperparameters_print_readably_and_round_trip() {
        for v in [2.5942570536546676e-8, 0.0000027424446836296227, 549.9198909809619, 1e-5, 0.4, 3e12] {
            let s = readable(v);
            assert!(s.len() <= 24, "{s}");
            assert_eq!(s.parse::<f64>().unwrap(), v, "{s}");
        }
        assert_eq!(readable(2.5942570536546676e-8), "2.5942570536546676e-8");
        assert_eq!(readable(0.4), "0.4");
        let h = CbdHyperparameters {
            joint_axes: vec![cbd_protocol::JointKernelAxis::Periodic { b: 0.25 }; 2],
            joint_gamma: 0.0000027424446836296227,
            task_width: 549.9,
            task_gamma: 0.4,
            sigma: 2.5942570536546676e-8,
            configuration: None,
        };
        let line = describe(&h);
        assert!(line.contains("sigma 2.5942570536546676e-8") && line.contains("gamma 2.7424446836296227e-6"), "{line}");
        assert!(!line.contains("0.00000"), "{line}");
    }

    #[test]
    fn rows_at_the_nominal_are_refused_with_the_cause_and_noisy_ones_are_not() {
        let nominal = crate::simulate::rr::nominal();
        let mut exact = Measurements::new(2, 2);
        let mut noisy = Measurements::new(2, 2);
        for i in 0..20 {
            let q = [0.3 * i as f64, 1.0 - 0.1 * i as f64];
            let y = crate::nominal::positions(&nominal, &q, 2);
            exact.push(&q, &y);
            noisy.push(&q, &[y[0] + 1e-6 * (i as f64).sin(), y[1]]);
        }
        let why = exact_nominal(&nominal, &exact).expect("exact rows refused");
        assert!(why.contains("the nominal model's own") && why.contains("no noise"), "{why}");
        assert_eq!(exact_nominal(&nominal, &noisy), None);
        let settings = Settings::default();
        let e = calibrate(&nominal, &exact, &settings).unwrap_err().to_string();
        assert!(e.contains("the nominal model's own"), "{e}");
    }

    #[test]
    fn no_choice_claims_folds_the_rows_cannot_give() {
        let mut three = Measurements::new(2, 2);
        for i in 0..3 {
            three.push(&[i as f64, 0.0], &[0.0, i as f64]);
        }
        let why = crate::data::stage_rows::too_few_to_cross_validate(&three, 4).unwrap();
        assert_eq!(why, "too few poses to cross-validate: 3, where 4 folds need at least 8");
        let mut eight = three.clone();
        for i in 3..8 {
            eight.push(&[i as f64, 0.0], &[0.0, i as f64]);
        }
        assert_eq!(crate::data::stage_rows::too_few_to_cross_validate(&eight, 4), None);
    }
}

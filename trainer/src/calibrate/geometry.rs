//! Whether the chain's geometric group (DH parameters, base, tool; a planar arm's in-plane group)
//! is calibrated before the flows: two hypotheses, "CbD on the nominal" and "CbD with the geometry
//! calibrated", scored by CbD's own evidence on the same rows — the group marginalised as explicit
//! basis functions with a broad prior (`evidence::GeometricBasis`, docs/DESIGN.md §3) — or, where no
//! evidence runs (the paper's hyperparameters, every value given), by k-fold cross-validation.

use super::hyperparameters::{choose_cbd_hyperparameters_with_overrides, normalisation_for, options_for};
use super::Settings;
use crate::data::stage_rows::StageRows;
use crate::data::Measurements;
use crate::evidence::{CbdHyperparameters, Evidence, GeometricBasis};
use crate::parametric::{calibrate_dh, linearised_group, DhCalibration, DhCalibrationOptions, DhFitStats};
use cbd_protocol::{Integrator, IntegratorMethod, NominalModel, Normalisation};

/// Which base model CbD deforms.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Geometry {
    /// Decided from the data: CbD's evidence, else cross-validation.
    Auto,
    /// The nominal chain as given.
    Nominal,
    /// The geometric group calibrated first (Levenberg–Marquardt), the blob carrying that chain.
    Calibrated,
}

/// One hypothesis: the base model, its DH fit, and CbD's hyperparameters for it.
#[derive(Debug, Clone)]
pub struct Hypothesis {
    pub base: NominalModel,
    pub dh: Option<DhFitStats>,
    pub hyperparameters: CbdHyperparameters,
    /// The search that chose the hyperparameters.
    pub evidence: Option<Evidence>,
}

/// The choice and what decided it (the JSON's `geometry`).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct GeometryChoice {
    /// `nominal` or `calibrated`.
    pub chosen: Geometry,
    /// "given", "evidence", "k-fold cross-validation", or why the other hypothesis was not scored.
    pub by: String,
    /// Each hypothesis' score, when both were scored.
    pub scores: Option<GeometryScores>,
}

/// The two hypotheses' scores on the same rows.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct GeometryScores {
    /// "log evidence" (nats, higher wins) or "held-out RMS" (data units, lower wins).
    pub criterion: &'static str,
    pub nominal: f64,
    pub calibrated: f64,
    /// Rows the scores were computed on.
    pub rows: usize,
    /// Geometric parameters the calibrated hypothesis marginalised (evidence) or fitted.
    pub parameters: usize,
}

impl GeometryChoice {
    /// One line: the choice, what decided it and both scores.
    pub fn describe(&self) -> String {
        let chosen = match self.chosen {
            Geometry::Calibrated => "calibrated",
            _ => "nominal",
        };
        match &self.scores {
            Some(s) => format!(
                "geometry: {chosen} (by {}: {} nominal {}, calibrated {} on {} rows, {} geometric parameters identifiable at the calibrated chain)",
                self.by,
                s.criterion,
                short(s.nominal),
                short(s.calibrated),
                s.rows,
                s.parameters
            ),
            None => format!("geometry: {chosen} ({})", self.by),
        }
    }
}

fn short(v: f64) -> String {
    if v.abs() >= 1e-2 && v.abs() < 1e7 {
        format!("{v:.2}")
    } else {
        format!("{v:.4e}")
    }
}

/// The hypothesis "CbD on the nominal".
pub fn nominal_hypothesis(
    nominal: &NominalModel,
    data: &StageRows,
    norm: &Normalisation,
    settings: &Settings,
) -> crate::Result<Hypothesis> {
    let (hyperparameters, evidence) = choose_cbd_hyperparameters_with_overrides(nominal, data, norm, settings, None)?;
    Ok(Hypothesis { base: nominal.clone(), dh: None, hyperparameters, evidence })
}

/// The geometric group fitted by Levenberg–Marquardt, when the blob can carry the result: a DH
/// chain's (a planar blob holds link lengths only, not the base and joint offsets its group moves).
pub fn calibrated_chain(nominal: &NominalModel, data: &Measurements) -> crate::Result<DhCalibration> {
    if matches!(nominal, NominalModel::PlanarChain { .. }) {
        return Err(crate::Error::InvalidInput(
            "a planar arm's blob holds its link lengths only, not the base and joint offsets its geometric group moves: the calibrated geometry cannot be carried (`cbd compare` scores it as dh+cbd)".into(),
        ));
    }
    Ok(calibrate_dh(nominal, data, &DhCalibrationOptions::default())?)
}

/// The hypothesis "CbD with the geometry calibrated" on the fitted chain `fitted`: CbD's
/// hyperparameters by its evidence on the fitted chain's residual — the residual the fields are
/// fitted to (with the group marginalised instead, the six-joint arm's task field came out
/// near-affine and the test error 3.50e-2 mm against 3.33e-2).
fn calibrated_hypothesis(fitted: DhCalibration, data: &StageRows, norm: &Normalisation, settings: &Settings) -> crate::Result<Hypothesis> {
    Ok(Hypothesis { dh: Some(fitted.stats), ..nominal_hypothesis(&fitted.model, data, norm, settings)? })
}

/// The hypothesis `settings.geometry` asks for, or for `Auto` the better of the two; and the
/// DH-calibrated chain when it was fitted on the way, or, where none was and `with_chain`, the chain
/// fitted here (`nominal` as it stands where the DH fit cannot calibrate it): the drift test's chain
/// ([`super::drift_test::drift_of_chain`]), so that the chain is fitted once, in this stage.
pub fn choose_geometry(
    nominal: &NominalModel,
    data: &StageRows,
    norm: &Normalisation,
    settings: &Settings,
    with_chain: bool,
) -> crate::Result<(Hypothesis, GeometryChoice, Option<NominalModel>)> {
    let given = |chosen| GeometryChoice { chosen, by: "given".into(), scores: None };
    let (hypothesis, choice, chain) = match settings.geometry {
        Geometry::Nominal => (nominal_hypothesis(nominal, data, norm, settings)?, given(Geometry::Nominal), None),
        Geometry::Calibrated => {
            let fitted = calibrated_chain(nominal, &data.rows)?;
            let chain = fitted.model.clone();
            (calibrated_hypothesis(fitted, data, norm, settings)?, given(Geometry::Calibrated), Some(chain))
        }
        Geometry::Auto => {
            let (plain, calibrated, choice, chain) = decide(nominal, data, norm, settings, true)?;
            match calibrated {
                Some(h) if choice.chosen == Geometry::Calibrated => (h, choice, chain),
                _ => (plain, choice, chain),
            }
        }
    };
    let chain = match chain {
        None if with_chain => {
            Some(calibrate_dh(nominal, &data.rows, &DhCalibrationOptions::default()).map_or(nominal.clone(), |f| f.model))
        }
        chain => chain,
    };
    Ok((hypothesis, choice, chain))
}

/// What `Auto` chooses on these rows, without the calibrated hypothesis' own hyperparameters (what
/// `cbd compare` marks as the row `cbd fit` writes by default).
pub fn geometry_choice(nominal: &NominalModel, data: &Measurements, settings: &Settings) -> crate::Result<GeometryChoice> {
    let data = StageRows::new(data.clone(), &settings.cuts());
    let norm = normalisation_for(&data.normalisation, settings);
    Ok(decide(nominal, &data, &norm, &Settings { geometry: Geometry::Auto, ..settings.clone() }, false)?.2)
}

/// The calibrated side of the choice: the fitted chain's evidence with the group marginalised (the
/// score; `None` where no search runs or the group cannot be linearised) and, when asked, the
/// calibrated hypothesis itself.
struct CalibratedSide {
    score: Option<Evidence>,
    hypothesis: Option<Hypothesis>,
    /// The fitted chain.
    chain: NominalModel,
}

/// The calibrated side, or why the geometric group cannot be calibrated here.
fn calibrated_side(
    nominal: &NominalModel,
    data: &StageRows,
    norm: &Normalisation,
    settings: &Settings,
    with_hypothesis: bool,
) -> crate::Result<Result<CalibratedSide, String>> {
    let fitted = match calibrated_chain(nominal, &data.rows) {
        Ok(f) => f,
        Err(e) => return Ok(Err(format!("the geometric group cannot be calibrated here: {e}"))),
    };
    // The calibrated hypothesis' evidence comparable with the nominal's: the group marginalised
    // around the fit, on the same rows (only where the nominal's evidence is searched too).
    let searched = settings.searches_evidence(nominal);
    // The score and the hypothesis are independent searches: side by side too.
    let (score, hypothesis) = rayon::join(
        || -> crate::Result<Option<Evidence>> {
            match linearised_group(nominal, &fitted.stats, &data.rows).filter(|_| searched) {
                Some(group) => {
                    let basis = GeometricBasis::new(&group, &data.rows, norm);
                    Ok(choose_cbd_hyperparameters_with_overrides(&fitted.model, data, norm, settings, Some(&basis))?.1)
                }
                None => Ok(None),
            }
        },
        || with_hypothesis.then(|| calibrated_hypothesis(fitted.clone(), data, norm, settings)).transpose(),
    );
    Ok(Ok(CalibratedSide { score: score?, hypothesis: hypothesis?, chain: fitted.model }))
}

/// Both hypotheses scored: the nominal one, the calibrated one when `with_hypothesis` (`None`
/// otherwise, or when the group cannot be calibrated here: the choice then says why), the
/// choice and the fitted chain (`None` where the group cannot be calibrated here). The two sides
/// are independent and run side by side on the command's workers (the calibrated hypothesis then
/// before it is known to win: `cbd fit`'s time is the longer side's, not the sum); each gives the
/// same bits on one worker or two.
fn decide(
    nominal: &NominalModel,
    data: &StageRows,
    norm: &Normalisation,
    settings: &Settings,
    with_hypothesis: bool,
) -> crate::Result<(Hypothesis, Option<Hypothesis>, GeometryChoice, Option<NominalModel>)> {
    let (plain, calibrated) = rayon::join(
        || nominal_hypothesis(nominal, data, norm, settings),
        || calibrated_side(nominal, data, norm, settings, with_hypothesis),
    );
    let plain = plain?;
    let calibrated = match calibrated? {
        Ok(side) => side,
        Err(by) => return Ok((plain, None, GeometryChoice { chosen: Geometry::Nominal, by, scores: None }, None)),
    };
    let (scores, by) = match (&plain.evidence, &calibrated.score) {
        (Some(a), Some(b)) => (evidence_scores(a, b, b.geometric_parameters), "evidence".to_string()),
        _ => {
            // Too few poses for the folds: the nominal kept, and the line says so (it claimed
            // "4-fold cross-validation … on 3 rows" beside the scheme's "too few rows").
            let folds = match &data.folds {
                Ok(folds) => folds,
                Err(why) => {
                    let by = format!("{why}: the nominal kept, as without evidence the calibrated geometry cannot be scored");
                    return Ok((plain, None, GeometryChoice { chosen: Geometry::Nominal, by, scores: None }, Some(calibrated.chain)));
                }
            };
            (cross_validated_scores(nominal, data, folds, norm, settings, &plain)?, format!("{}-fold cross-validation", folds.len()))
        }
    };
    let calibrated_wins = match scores.criterion {
        "log evidence" => scores.calibrated > scores.nominal,
        _ => scores.calibrated < scores.nominal,
    };
    let chosen = if calibrated_wins { Geometry::Calibrated } else { Geometry::Nominal };
    Ok((plain, calibrated.hypothesis, GeometryChoice { chosen, by, scores: Some(scores) }, Some(calibrated.chain)))
}

/// The two evidences where they are comparable: on every row when both were computed there, else
/// on the kernel form's evenly spaced rows, which the two searches share.
fn evidence_scores(nominal: &Evidence, calibrated: &Evidence, parameters: usize) -> GeometryScores {
    let (a, b, rows) = if nominal.rows_used == calibrated.rows_used {
        (nominal.log_evidence, calibrated.log_evidence, nominal.rows_used)
    } else {
        (nominal.subset_log_evidence, calibrated.subset_log_evidence, nominal.subset_rows)
    };
    GeometryScores { criterion: "log evidence", nominal: a, calibrated: b, rows, parameters }
}

/// Held-out RMS of both hypotheses on `folds` of `data` (each fold: the DH fit on its training rows,
/// then CbD with the given hyperparameters, Euler × 1), when no evidence was computed.
fn cross_validated_scores(
    nominal: &NominalModel,
    data: &StageRows,
    folds: &[(Measurements, Measurements)],
    norm: &Normalisation,
    settings: &Settings,
    plain: &Hypothesis,
) -> crate::Result<GeometryScores> {
    let mut quiet = settings.clone();
    quiet.solver.verbose = false;
    let opts = options_for(&plain.hyperparameters, norm, Integrator { method: IntegratorMethod::Euler, steps: 1 }, &quiet);
    let (mut sse, mut count, mut parameters) = ([0.0; 2], 0usize, 0);
    for (train, held) in folds {
        let dh = calibrate_dh(nominal, train, &DhCalibrationOptions::default())?;
        parameters = dh.stats.rank;
        for (k, base) in [nominal, &dh.model].into_iter().enumerate() {
            let fit = crate::solver::fit_cbd(base, train, &opts)?;
            let predicted = crate::predict::evaluate_blob(&fit.blob, &held.joints)?;
            sse[k] += predicted.iter().zip(&held.positions).map(|(a, b)| (a - b).powi(2)).sum::<f64>();
        }
        count += held.len();
    }
    let rms = |s: f64| (s / count.max(1) as f64).sqrt();
    Ok(GeometryScores { criterion: "held-out RMS", nominal: rms(sse[0]), calibrated: rms(sse[1]), rows: data.len(), parameters })
}

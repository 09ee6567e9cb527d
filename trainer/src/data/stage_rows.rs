//! The rows a calibration's stages take, cut once in the data layer before any stage runs (issue
//! 52): the training rows, their task-space normalisation, the evidence's evenly spaced rows, the
//! cross-validation's folds and the drift test's window. The stages (the geometry choice, the
//! evidence, the scheme, the drift test) take these pieces and no longer cut the rows themselves.

use super::{Measurements, RowOrder};
use cbd_protocol::Normalisation;

/// What the stages ask of the rows: the sizes of the cuts (`calibrate::Settings::cuts`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Cuts {
    /// The evidence's (N m) unknowns at most (`EvidenceOptions::max_unknowns`).
    pub evidence_unknowns: usize,
    /// The evidence's coarse rows' unknowns (`EvidenceOptions::coarse_unknowns`).
    pub coarse_unknowns: usize,
    /// Folds of the cross-validations (the scheme's, and the geometry's where no evidence runs).
    pub folds: usize,
    /// Poses the drift test takes (the first this many in measurement order), when it runs.
    pub drift_window: Option<usize>,
}

/// The training rows and every subset a stage takes of them.
#[derive(Debug, Clone)]
pub struct StageRows {
    /// Every training row.
    pub rows: Measurements,
    /// Their task-space normalisation ([`Measurements::normalisation`]).
    pub normalisation: Normalisation,
    /// The evidence's rows.
    pub evidence: EvidenceRows,
    /// (training rows, held-out rows) per fold ([`Measurements::fold`]), or why the poses are too
    /// few to cross-validate ([`too_few_to_cross_validate`]).
    pub folds: Result<Vec<(Measurements, Measurements)>, String>,
    /// The drift test's rows: the window's poses in measurement order; `None` when no test runs
    /// (not asked, or rows declared unordered: a grid has no time of measurement).
    pub drift: Option<Measurements>,
}

/// The evidence's rows: all, or evenly spaced whole poses within its unknowns ([`evidence_rows`]),
/// and of those the coarse rows its starts are screened on and the medium rows the configuration
/// field's search climbs on.
#[derive(Debug, Clone)]
pub struct EvidenceRows {
    /// The rows' indices among the training rows.
    pub indices: Vec<usize>,
    pub used: Measurements,
    /// The coarse rows' indices among `used`.
    pub coarse_indices: Vec<usize>,
    /// The coarse rows, when fewer than `used`.
    pub coarse: Option<Measurements>,
    /// Half the evidence's unknowns, evenly spaced through `used`: when there are coarse rows and
    /// these are fewer than `used` and more than the coarse.
    pub medium: Option<Measurements>,
}

impl StageRows {
    /// `rows` and their cuts.
    pub fn new(rows: Measurements, cuts: &Cuts) -> StageRows {
        let normalisation = rows.normalisation();
        let evidence = EvidenceRows::new(&rows, cuts.evidence_unknowns, cuts.coarse_unknowns);
        let folds = match too_few_to_cross_validate(&rows, cuts.folds) {
            Some(why) => Err(why),
            None => Ok((0..cuts.folds).map(|fold| rows.fold(cuts.folds, fold)).collect()),
        };
        let drift = cuts.drift_window.filter(|_| rows.order == RowOrder::Measured).map(|window| {
            let tested: Vec<usize> = (0..rows.len().min(window.saturating_mul(rows.points_per_pose.max(1)))).collect();
            rows.subset(&tested)
        });
        StageRows { rows, normalisation, evidence, folds, drift }
    }

    pub fn len(&self) -> usize {
        self.rows.len()
    }

    pub fn is_empty(&self) -> bool {
        self.rows.is_empty()
    }
}

impl EvidenceRows {
    /// The evidence's rows of `data` within `max_unknowns`, their coarse rows within
    /// `coarse_unknowns` and their medium rows within `max_unknowns / 2`.
    pub fn new(data: &Measurements, max_unknowns: usize, coarse_unknowns: usize) -> EvidenceRows {
        let indices = evidence_rows(data, max_unknowns);
        let used = data.subset(&indices);
        let coarse_indices = evidence_rows(&used, coarse_unknowns);
        let coarse = (coarse_indices.len() < used.len()).then(|| used.subset(&coarse_indices));
        let medium_indices = evidence_rows(&used, max_unknowns / 2);
        let medium = (coarse.is_some() && medium_indices.len() < used.len() && medium_indices.len() > coarse_indices.len())
            .then(|| used.subset(&medium_indices));
        EvidenceRows { indices, used, coarse_indices, coarse, medium }
    }
}

/// The rows an evidence takes: all, or evenly spaced whole poses when N m exceeds `max_unknowns`.
pub fn evidence_rows(data: &Measurements, max_unknowns: usize) -> Vec<usize> {
    data.evenly_spaced_pose_rows((max_unknowns / data.task_dim.max(1)).max(3))
}

/// Why `data` is too few poses for `folds`-fold cross-validation (each fold holds out at least one
/// pose and trains on the rest: at least two poses a fold), or `None`. One rule for every choice
/// the fit makes by cross-validation (the scheme's, the geometry's), so that no line claims a
/// k-fold cross-validation the rows could not give.
pub fn too_few_to_cross_validate(data: &Measurements, folds: usize) -> Option<String> {
    let poses = data.pose_count();
    (poses < 2 * folds).then(|| format!("too few poses to cross-validate: {poses}, where {folds} folds need at least {}", 2 * folds))
}

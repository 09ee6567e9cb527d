//! Does a calibration still hold (`cbd check`, docs/DESIGN.md "cbd check", issue 50): fresh poses
//! against the blob's own posterior predictive distribution; when it changed, the change named from
//! the library of physical changes, and refitted when asked.

use super::blob_rows::{evaluate_rows, finite_statistics, recorded_sigma};
use super::{ArmModel, Dataset, DecodedBlob};
use crate::error::{Context, Error, Result};
use crate::evaluation::check::name::{name_change, NameError, Named};
use crate::evaluation::check::update::{update, Updated};
use crate::evaluation::check::{Check, CheckError, CheckOptions, Verdict};
use crate::report::noise_floor::{FloorVerdict, NoiseFloor};
use crate::report::stats::ErrorStats;
use std::path::Path;

/// Kernel support below which a fresh pose counts as extrapolating.
pub const EXTRAPOLATION_THRESHOLD: f64 = 0.05;

/// What the check is asked.
#[derive(Debug, Clone, Copy)]
pub struct CheckSettings {
    /// The test's level: "changed" when p < alpha (0 < alpha < 1).
    pub alpha: f64,
    /// Fit the fresh rows' rigid frame first (a tracker set up anew).
    pub register: bool,
    /// When it changed and the change is named: refit the named change on the fresh poses.
    pub update: bool,
}

/// The check's outcome (`cbd check`'s lines and JSON).
pub struct Checked {
    pub rows: usize,
    /// The model file's length unit, for the lines.
    pub unit: &'static str,
    pub alpha: f64,
    /// The statistic, its verdict, the registered frame and what naming the change reads.
    pub result: Check,
    /// The blob's error on the fresh rows, against the floor of rows measured at another time
    /// (σ and the recorded drift).
    pub calibrated: ErrorStats,
    pub floor: NoiseFloor,
    pub floor_verdict: FloorVerdict,
    /// The blob records a drift, which the predictive covariance carries.
    pub with_drift: bool,
    /// The named change, when the calibration changed and naming ran.
    pub named: Option<Named>,
    /// The refit asked for (`None`: not asked, or the calibration holds): the refitted blob, or why
    /// there is none (the change not named, or its refit refused). An error here does not hide the
    /// check's own outcome, which a front reports first.
    pub updated: Option<std::result::Result<Updated, String>>,
    /// Fresh poses far from every measured configuration.
    pub extrapolating: usize,
}

impl CheckSettings {
    /// Rejects out-of-range values before any work, naming the flag (a front calls it before
    /// reading its files; [`check`] again).
    pub fn validate(&self) -> Result<()> {
        if !(self.alpha > 0.0 && self.alpha < 1.0) {
            return Err(Error::InvalidInput(format!(
                "--alpha must be a number between 0 and 1 (exclusive), got {}",
                crate::error::number(self.alpha)
            )));
        }
        Ok(())
    }
}

/// Checks `blob` (decoded from `bytes`) on the fresh rows `data` of `arm`.
pub fn check(arm: &ArmModel, blob: DecodedBlob<'_>, bytes: &[u8], data: &Dataset, settings: &CheckSettings) -> Result<Checked> {
    settings.validate()?;
    let (model, blob_path, data_path) = (blob.model, blob.source, data.source.as_path());
    let (rows, lines) = (&data.imported.measurements, &data.imported.lines);
    if model.n_joints() != rows.n_joints || model.task_dim() != rows.task_dim {
        return Err(Error::InvalidInput(format!(
            "{}: {} joints and {}-D positions, but {} has {} joints and {}-D positions",
            data_path.display(),
            rows.n_joints,
            rows.task_dim,
            blob_path.display(),
            model.n_joints(),
            model.task_dim()
        )));
    }
    let Some(sigma) = recorded_sigma(&model, blob_path)? else {
        return Err(Error::InvalidInput(format!("{}: {}", blob_path.display(), CheckError::NoSigma)));
    };
    let m = model.task_dim();
    let need = crate::evaluation::check::covariance::covariance_bytes(model.n_points as usize, rows.len(), m);
    if let Some(available) = crate::memory::available_bytes().filter(|a| need > *a) {
        return Err(Error::InvalidInput(format!(
            "{}: its {} measurement points and the {} fresh rows need about {} for the check's covariance, more than the {} this process may use; raise the memory limit",
            blob_path.display(),
            model.n_points,
            rows.len(),
            crate::memory::gigabytes(need),
            crate::memory::gigabytes(available)
        )));
    }
    let mut storage = vec![0.0; cbd_runtime::storage_len_for(&model)];
    let mut cal = cbd_runtime::Calibrator::from_model(model.clone(), &mut storage).context(blob_path.display())?;
    crate::predict::check_calibrator(&mut cal).context(blob_path.display())?;
    let (predicted, extrapolating) = evaluate_rows(&mut cal, rows, lines, blob_path, data_path, EXTRAPOLATION_THRESHOLD)?;
    // A blob whose chain is not the model file's carries a DH-calibrated geometry (`cbd fit`'s
    // default when the evidence chooses it): its parameters' uncertainty goes into C.
    let geometry = model.nominal != arm.nominal;
    let register = settings.register || arm.register_base();
    let options = CheckOptions { alpha: settings.alpha, register, geometry };
    let result = crate::evaluation::check::check(&model, rows, &predicted, options).map_err(|e| {
        let file = if e == CheckError::NotPositiveDefinite || e == CheckError::NoSigma { blob_path } else { data_path };
        Error::InvalidInput(format!("{}: {e}", file.display()))
    })?;
    let calibrated = finite_statistics("calibrated", &predicted, &result.measured, m, lines, data_path)?;
    let unit = arm.spec.model_length_unit.name();
    // What a perfect model's error is on rows measured at another time: σ, and the recorded drift.
    let drift_sd = model.drift.map_or(0.0, |d| d.sd);
    let with_drift = model.drift.is_some();
    let floor = NoiseFloor::new(
        (sigma * sigma + drift_sd * drift_sd).sqrt(),
        m,
        if with_drift { "σ and the calibration's drift, recorded in the blob" } else { "the calibration's σ, recorded in the blob" },
    );
    let floor_verdict = floor.verdict(calibrated.mean, rows.len());
    // Naming the change (issue 50 item 3): only when it changed.
    let named = match result.verdict {
        Verdict::Holds => None,
        Verdict::Changed => match name_change(&model, rows, &result.residual, &result.covariance, result.tangent.as_ref(), unit) {
            Ok(named) => Some(named),
            Err(e) => {
                errln!("warning: the change is not named: {}", name_error(e));
                None
            }
        },
    };
    let updated = match (&named, settings.update && result.verdict == Verdict::Changed) {
        (_, false) => None,
        (Some(named), true) => {
            let groups: Vec<_> = named.changes.iter().map(|c| c.candidate).collect();
            let frame = crate::data::import_frame::import_frame(&arm.spec);
            Some(
                update(&model, bytes, frame, rows, &result.measured, &result.covariance, result.tangent.as_ref(), &groups)
                    .map_err(|e| format!("--update: {e}")),
            )
        }
        (None, true) => Some(Err("--update: the change is not named, so there is nothing to update".into())),
    };
    Ok(Checked {
        rows: rows.len(),
        unit,
        alpha: settings.alpha,
        result,
        calibrated,
        floor,
        floor_verdict,
        with_drift,
        named,
        updated,
        extrapolating,
    })
}

impl Checked {
    /// The named change's effects as JSON (empty when the calibration holds or nothing explains it).
    fn changes_json(&self) -> Vec<serde_json::Value> {
        self.named.as_ref().map_or_else(Vec::new, |n| n.changes.iter().map(|c| c.to_json()).collect())
    }

    /// `cbd check --json`'s value; `out` is where an updated blob was written.
    pub fn to_json(&self, out: Option<&Path>) -> serde_json::Value {
        let s = &self.result.statistic;
        let mut v = serde_json::json!({
            "verdict": self.result.verdict,
            "p_value": s.p_value,
            "statistic": s.statistic,
            "dof": s.dof,
            "alpha": self.alpha,
            "rows": self.rows,
            "changes": self.changes_json(),
            "calibrated": self.calibrated,
            "noise_floor": {"floor": self.floor, "calibrated": self.floor_verdict},
            "extrapolating": self.extrapolating,
        });
        if let Some(frame) = &self.result.frame {
            v["frame"] = frame.to_json();
        }
        if let Some(named) = &self.named {
            v["after_change"] = serde_json::json!({
                "statistic": named.after.statistic,
                "dof": named.after.dof,
                "p_value": named.after.p_value,
                "loo_log_density_before": named.evidence_before,
                "loo_log_density_after": named.evidence_after,
                "not_offered": named.excluded.iter().map(|(w, why)| serde_json::json!({"effect": w, "why": why})).collect::<Vec<_>>(),
            });
        }
        if let Some(Ok(u)) = &self.updated {
            v["update"] = serde_json::json!({
                "out": out.map(|p| p.display().to_string()),
                "parent_sha256": u.parent,
                "groups": u.changes.iter().map(|(g, v)| serde_json::json!({"effect": g.spelling(), "values": v})).collect::<Vec<_>>(),
                "before": u.before,
                "after": u.held_out,
                "after_in_sample": u.in_sample,
                "held_out_blocks": u.blocks,
            });
        }
        v
    }

    /// One line of a check log (`cbd check --log`; `cbd report --checks` draws them): the floor and
    /// the top of its band (the largest mean error still at the floor over these rows) beside the
    /// error. `time` as UTC text, `blob` and `data` as the log names them.
    pub fn log_line(&self, time: &str, blob: &str, data: &str) -> serde_json::Value {
        let s = &self.result.statistic;
        serde_json::json!({
            "time": time,
            "blob": blob,
            "data": data,
            "p_value": s.p_value,
            "mean_error": self.calibrated.mean,
            "verdict": self.result.verdict,
            "statistic": s.statistic,
            "dof": s.dof,
            "alpha": self.alpha,
            "rows": self.rows,
            "unit": self.unit,
            "floor": self.floor.mean_error,
            "floor_limit": self.floor.at_floor_limit(self.rows),
            "changes": self.changes_json(),
        })
    }
}

fn name_error(e: NameError) -> &'static str {
    match e {
        NameError::NotDhChain => "the library's changes are those of a DH chain measured in 3-D",
        NameError::NotPositiveDefinite => "the fit of the library's changes is not defined on these rows",
    }
}

//! A calibration evaluated on measurements: the nominal's and the blob's position errors, against
//! the noise floor and the drift the blob records.

use super::blob_rows::{evaluate_rows, finite_statistics, recorded_sigma};
use super::{ArmModel, Dataset};
use crate::error::{Context, Error, Result};
use crate::evaluation::pose_errors::PoseErrors;
use crate::report::noise_floor::NoiseFloor;
use crate::report::stats::ErrorStats;
use std::path::Path;

/// A blob decoded (and checked to fit the arm) by the front, with what messages call it.
pub struct DecodedBlob<'b> {
    pub model: cbd_protocol::Model<'b>,
    /// The blob's source in messages (its file's path).
    pub source: &'b Path,
}

/// The errors of the nominal and the calibrated model on a dataset (`cbd eval`).
pub struct Evaluation {
    pub rows: usize,
    /// Rows whose kernel support is below the threshold: extrapolation.
    pub extrapolating: usize,
    pub nominal: ErrorStats,
    pub calibrated: ErrorStats,
    /// The σ the calibration assumed as a floor (`None`: a blob of format 6 or older records none).
    pub noise_floor: Option<NoiseFloor>,
    /// The drift the calibration's rows carried (format 8) and the floor with it.
    pub drift: Option<(cbd_protocol::RowDrift, NoiseFloor)>,
    /// Per tool point and the tool frame, for the nominal and the calibrated model (several tool points).
    pub poses: [(&'static str, Option<PoseErrors>); 2],
    /// The nominal's and the calibrated model's positions, row by row (for figures).
    pub nominal_positions: Vec<f64>,
    pub calibrated_positions: Vec<f64>,
}

impl Evaluation {
    /// `cbd eval --json`'s value (keys `rows`, `extrapolating`, `nominal`, `calibrated`, …).
    pub fn to_json(&self) -> serde_json::Value {
        let verdict = |s: &ErrorStats| self.noise_floor.as_ref().map(|f| f.verdict(s.mean, self.rows));
        let pose_json = |k: usize| self.poses[k].1.as_ref().map(PoseErrors::to_json);
        let mut v = serde_json::json!({"rows": self.rows, "extrapolating": self.extrapolating, "nominal": self.nominal, "calibrated": self.calibrated});
        if let Some(f) = &self.noise_floor {
            v["noise_floor"] = serde_json::json!({"floor": f, "nominal": verdict(&self.nominal), "calibrated": verdict(&self.calibrated)});
        }
        if let Some((d, with)) = &self.drift {
            v["drift"] = serde_json::json!({"sd": d.sd, "length": d.length, "floor": with, "calibrated": with.verdict(self.calibrated.mean, self.rows)});
        }
        if self.poses[0].1.is_some() {
            v["pose"] = serde_json::json!({"nominal": pose_json(0), "calibrated": pose_json(1)});
        }
        v
    }
}

/// Evaluates `blob` on `data` beside `arm`'s nominal; `extrapolation_threshold` is the kernel
/// support below which a row counts as extrapolating.
pub fn evaluate(arm: &ArmModel, blob: DecodedBlob<'_>, data: &Dataset, extrapolation_threshold: f64) -> Result<Evaluation> {
    let (source, blob_source) = (data.source.as_path(), blob.source);
    let (data, lines) = (&data.imported.measurements, &data.imported.lines);
    let model = blob.model;
    let mut nominal = arm.nominal.clone();
    take_registered_base(arm, &mut nominal, &model.nominal, data, source, blob_source)?;
    if model.nominal != nominal {
        errln!(
            "note: {} carries its own nominal model (e.g. DH-calibrated); errors are reported against the model file's nominal",
            blob_source.display()
        );
    }
    if model.n_joints() != data.n_joints || model.task_dim() != data.task_dim {
        return Err(Error::InvalidInput(format!(
            "{}: the model has {} joints and {}-D positions, but {} has {} joints and {}-D positions",
            blob_source.display(),
            model.n_joints(),
            model.task_dim(),
            source.display(),
            data.n_joints,
            data.task_dim
        )));
    }
    let m = model.task_dim();
    let mut storage = vec![0.0; cbd_runtime::storage_len_for(&model)];
    let mut cal = cbd_runtime::Calibrator::from_model(model, &mut storage).context(blob_source.display())?;
    crate::predict::check_calibrator(&mut cal).context(blob_source.display())?;
    let tool_points = cal.model().nominal.tool_points().to_vec();
    let (predicted, far) = evaluate_rows(&mut cal, data, lines, blob_source, source, extrapolation_threshold)?;
    let nominal_pred = crate::nominal::positions(&nominal, &data.joints, m);
    let before = finite_statistics("nominal", &nominal_pred, &data.positions, m, lines, source)?;
    let after = finite_statistics("calibrated", &predicted, &data.positions, m, lines, source)?;
    // The σ the calibration assumed, which the blob records (format 7; older blobs: no floor).
    let floor = recorded_sigma(cal.model(), blob_source)?.map(|sigma| NoiseFloor::new(sigma, m, "the calibration's, recorded in the blob"));
    // The drift the calibration's rows carried (format 8): not in σ, but in the error of rows
    // measured at another time, as these may be.
    let drift = cal.model().drift.zip(cal.model().noise_sigma).map(|(d, sigma)| {
        let with = NoiseFloor::new((sigma * sigma + d.sd * d.sd).sqrt(), m, "σ and the calibration's drift, recorded in the blob");
        (d, with)
    });
    let poses = [("nominal", &nominal_pred), ("calibrated", &predicted)]
        .map(|(name, p)| (name, PoseErrors::of(&tool_points, p, &data.positions, m)));
    Ok(Evaluation {
        rows: data.len(),
        extrapolating: far,
        nominal: before,
        calibrated: after,
        noise_floor: floor,
        drift,
        poses,
        nominal_positions: nominal_pred,
        calibrated_positions: predicted,
    })
}

/// A base declared unknown was registered when the blob was fitted, on its training rows: the
/// nominal row uses that base (joint 1's constant part folded in when the blob's chain is
/// DH-calibrated), never one registered on the rows being evaluated.
fn take_registered_base(
    arm: &ArmModel,
    nominal: &mut cbd_protocol::NominalModel,
    fitted: &cbd_protocol::NominalModel,
    data: &crate::data::Measurements,
    source: &Path,
    blob_source: &Path,
) -> Result<()> {
    let (Some(path), true) = (&arm.path, arm.register_base()) else { return Ok(()) };
    let (cbd_protocol::NominalModel::DhChain(chain), cbd_protocol::NominalModel::DhChain(fitted)) = (&mut *nominal, fitted) else {
        return Err(Error::InvalidInput(format!(
            "{}: the base is declared unknown but {} holds no DH chain to take the registered base from",
            path.display(),
            blob_source.display()
        )));
    };
    let rms_before = crate::parametric::base_registration::rms_from(chain, data);
    let base = crate::parametric::base_registration::folded_base(chain, fitted);
    chain.base = base.to_transform();
    let r = crate::parametric::base_registration::Registration {
        base,
        rms_before,
        rms_after: crate::parametric::base_registration::rms_from(chain, data),
        refined: true,
        stopped_at_limit: None,
    };
    errln!("{}: {} (as fitted, from {})", source.display(), r.describe(arm.length_unit()), blob_source.display());
    Ok(())
}

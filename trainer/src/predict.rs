//! Evaluating a blob with the runtime, as a controller would.

use crate::error::{Error, Result};
use cbd_runtime::Calibrator;

/// Most of a model's own training configurations [`check_calibrator`] evaluates.
const CHECKED_CONFIGURATIONS: usize = 64;

/// A blob can pass its checksum and every field check and still be damaged (or built by hand):
/// momenta so large that the calibrated positions overflow. Such a model is refused before it is
/// used: at up to 64 of its own training configurations (evenly spaced) every calibrated position
/// must be finite and within ±1e100 in the model's unit, the bound every imported measurement
/// obeys (a model that fits its data predicts near them). The message names the configuration.
pub fn check_calibrator(cal: &mut Calibrator) -> std::result::Result<(), DamagedModel> {
    use crate::limits::MAX_MAGNITUDE;
    let n = cal.model().n_joints().max(1);
    let points: Vec<f64> = cal.model().points.iter().collect();
    let count = points.len() / n;
    let step = count.div_ceil(CHECKED_CONFIGURATIONS).max(1);
    for (k, q) in points.chunks_exact(n).enumerate().step_by(step) {
        let position: Vec<f64> = match cal.evaluate(q) {
            Ok(e) => e.position().iter().copied().collect(),
            Err(error) => return Err(DamagedModel::Unevaluable { configuration: k + 1, count, error }),
        };
        if let Some(&value) = position.iter().find(|v| !(v.abs() <= MAX_MAGNITUDE)) {
            return Err(DamagedModel::OutOfRange { value, configuration: k + 1, count });
        }
    }
    Ok(())
}

/// Why [`check_calibrator`] refused a model: at its own training `configuration` (1-based) of
/// `count`, the blob is damaged.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DamagedModel {
    /// The runtime could not evaluate it there.
    #[error("the model cannot be evaluated at its own training configuration {configuration} of {count}: {error}: the blob is damaged; fit it again")]
    Unevaluable { configuration: usize, count: usize, error: cbd_runtime::Error },
    /// A calibrated position there is not finite or beyond ±1e100.
    #[error("the model evaluates to {value:.3e} at its own training configuration {configuration} of {count}, beyond ±{:e}: the blob is damaged; fit it again", crate::limits::MAX_MAGNITUDE)]
    OutOfRange { value: f64, configuration: usize, count: usize },
}

impl From<DamagedModel> for Error {
    fn from(e: DamagedModel) -> Error {
        Error::stage("blob check", e)
    }
}

/// Loads `blob` with the runtime and evaluates it at every configuration of `joints`
/// (row-major); returns positions (row-major, user units).
pub fn evaluate_blob(blob: &[u8], joints: &[f64]) -> Result<Vec<f64>> {
    let model = cbd_protocol::decode(blob)?;
    let (n, m) = (model.n_joints(), model.task_dim());
    let mut storage = vec![0.0; cbd_runtime::storage_len_for(&model)];
    let mut cal = Calibrator::from_model(model, &mut storage)?;
    if joints.len() % n != 0 {
        return Err(Error::InvalidInput(format!("configurations have {} values, not a multiple of {n} joints", joints.len())));
    }
    let mut out = Vec::with_capacity(joints.len() / n * m);
    // Row r of data with several tool points is tool point r mod m_p (pose-major rows).
    let points = cal.model().nominal.tool_point_count();
    for (row, q) in joints.chunks_exact(n).enumerate() {
        let e = cal.evaluate_point(q, row % points).map_err(|error| Error::Evaluate { row, error })?;
        out.extend(e.position().iter());
    }
    Ok(out)
}

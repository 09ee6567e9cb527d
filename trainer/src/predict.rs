//! Evaluating a blob with the runtime, as a controller would.

use crate::error::{Error, Result};
use cbd_runtime::Calibrator;

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
    for (row, q) in joints.chunks_exact(n).enumerate() {
        let e = cal.evaluate(q).map_err(|error| Error::Evaluate { row, error })?;
        out.extend(e.position().iter());
    }
    Ok(out)
}

//! A blob evaluated on measured rows: what `face::evaluate` and `cbd check` share (and `cbd plan
//! --check` the σ), so that each does not carry its own copy.

use crate::error::{Error, Result};
use crate::report::stats::ErrorStats;
use std::path::{Path, PathBuf};

/// The calibration's σ the blob records (`None`: format 6 or older), refused outside the bound
/// table's range for a positive scale.
pub(crate) fn recorded_sigma(model: &cbd_protocol::Model<'_>, path: &Path) -> Result<Option<f64>> {
    match model.noise_sigma.and_then(|sigma| crate::limits::positive_scale_out_of_bounds("noise_sigma", sigma)) {
        Some(refusal) => Err(Error::InvalidInput(format!("{}: {refusal} (the calibration's σ, recorded in the blob)", path.display()))),
        None => Ok(model.noise_sigma),
    }
}

/// The blob's positions at every row of `data` (row i is tool point i mod m_p: pose-major rows,
/// docs/DESIGN.md §12) and how many rows have kernel support below `threshold` (extrapolating): the
/// evaluation `cbd eval` and `cbd check` share. A failure names the blob or the data's line.
pub(crate) fn evaluate_rows(
    cal: &mut cbd_runtime::Calibrator<'_>,
    data: &crate::data::Measurements,
    lines: &[u64],
    blob: &std::path::Path,
    path: &std::path::Path,
    threshold: f64,
) -> Result<(Vec<f64>, usize)> {
    let mut predicted = Vec::with_capacity(data.positions.len());
    let mut far = 0;
    let points = cal.model().nominal.tool_point_count();
    for i in 0..data.len() {
        let line = lines.get(i).copied().unwrap_or(0);
        let e = cal.evaluate_point(data.joints(i), i % points).map_err(|e| evaluation_error(e, blob, path, line))?;
        if e.is_extrapolating(threshold) {
            far += 1;
        }
        predicted.extend(e.position().iter());
    }
    Ok((predicted, far))
}

/// Error statistics of one model, refused (not printed as inf/NaN, not written as JSON null) when
/// any row's error is not finite; the message names the first such row's line.
pub(crate) fn finite_statistics(
    model: &str,
    predicted: &[f64],
    measured: &[f64],
    dim: usize,
    lines: &[u64],
    data: &std::path::Path,
) -> Result<ErrorStats> {
    let errors = crate::report::stats::position_errors(predicted, measured, dim);
    if let Some(row) = errors.iter().position(|e| !e.is_finite()) {
        let line = lines.get(row).copied().unwrap_or(0);
        return Err(Error::AtLine {
            file: data.to_path_buf(),
            line,
            message: format!(
                "the {model} position error is not finite ({}): the positions or the model's values are too large to compare",
                errors[row]
            ),
        });
    }
    // Each error is below √(f64::MAX) here, so their mean cannot overflow for any real row count.
    Ok(ErrorStats::of_errors(&errors))
}

/// Who is to blame when the runtime fails on a row: the query (wrong joint count, non-finite) is
/// the data's fault; anything else — the flow diverging, a non-finite result — comes from the
/// blob's own values (kernel widths, momenta), since the importer only lets finite, bounded joint
/// values through.
fn evaluation_error(e: cbd_runtime::Error, blob: &std::path::Path, data: &std::path::Path, line: u64) -> Error {
    match e {
        cbd_runtime::Error::QueryDimension { .. } | cbd_runtime::Error::NonFiniteQuery { .. } => {
            Error::Runtime(e).context(format!("{}:{line}", data.display()))
        }
        _ => BlobFails { blob: blob.to_path_buf(), data: data.to_path_buf(), line, error: e }.into(),
    }
}

/// The runtime failed at a row of the data through the blob's own values ([`evaluation_error`]).
#[derive(Debug, thiserror::Error)]
#[error(
    "{}: the model fails at the configuration of {}:{line}: {error} (the blob's own values, e.g. its kernel widths, are out of range)",
    blob.display(),
    data.display()
)]
pub struct BlobFails {
    pub blob: PathBuf,
    pub data: PathBuf,
    pub line: u64,
    pub error: cbd_runtime::Error,
}

impl From<BlobFails> for Error {
    fn from(e: BlobFails) -> Error {
        Error::stage("eval", e)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    /// Issue 17 item 3: inf/NaN statistics were printed (and written as JSON null) with exit 0.
    #[test]
    fn eval_refuses_non_finite_statistics() {
        let lines = [2, 3];
        let e = finite_statistics("nominal", &[0.0, 0.0, 0.0, 0.0], &[1.0, 0.0, 1e300, 1e300], 2, &lines, Path::new("t.csv"))
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("t.csv:3: the nominal position error is not finite"), "{e}");
        let s = finite_statistics("nominal", &[0.0, 0.0], &[3.0, 4.0], 2, &lines, Path::new("t.csv")).unwrap();
        assert_eq!(s.mean, 5.0);
    }

    /// Issue 17 item 7: a blob whose kernel width makes the flow non-finite was blamed on the
    /// data file's line; the blob is named first.
    #[test]
    fn a_failing_blob_is_blamed_not_the_data_line() {
        let e = evaluation_error(cbd_runtime::Error::NonFiniteResult, Path::new("a.blob"), Path::new("test.csv"), 2).to_string();
        assert!(e.starts_with("a.blob: the model fails at the configuration of test.csv:2"), "{e}");
        let e =
            evaluation_error(cbd_runtime::Error::NonFiniteQuery { index: 0 }, Path::new("a.blob"), Path::new("test.csv"), 2).to_string();
        assert!(e.starts_with("test.csv:2: "), "{e}");
    }
}

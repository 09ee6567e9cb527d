//! The rows a fit takes, made ready once before any fit (issue 52): the nominal model checked
//! against every row read, at most the rows asked for (evenly spaced through the file), and a
//! given σ checked against their spread. The fit then only calibrates.

use super::csv_import::ImportedMeasurements;
use super::nominal_check::nominal_warnings;
use super::Measurements;
use cbd_protocol::NominalModel;
use std::path::Path;

/// Largest σ accepted, relative to the training positions' spread ([`check_sigma`]).
const MAX_SIGMA_PER_EXTENT: f64 = 1e3;

/// The training rows of `imported` (read from `file`) for a fit of `nominal`: its warnings said
/// (`registered`: the base was registered on these rows), at most `max_rows` of them, evenly
/// spaced, and `sigma` (`--sigma`) checked against them. The errors name the file.
pub fn fit_rows(
    nominal: &NominalModel,
    imported: &ImportedMeasurements,
    file: &Path,
    registered: bool,
    max_rows: Option<usize>,
    sigma: Option<f64>,
) -> crate::Result<Measurements> {
    for w in nominal_warnings(nominal, &imported.measurements, &imported.lines, file, registered)? {
        errln!("warning: {w}");
    }
    let all = &imported.measurements;
    let rows = match max_rows {
        Some(k) if k < all.len() => all.subset(&all.evenly_spaced_pose_rows(k)),
        _ => all.clone(),
    };
    check_sigma(sigma, &rows, file)?;
    Ok(rows)
}

/// `--sigma` against the training rows read from `file`: a noise σ over [`MAX_SIGMA_PER_EXTENT`] ×
/// the positions' spread (RMS distance from their mean) would swamp every measurement — a σ given
/// in another unit — and the fit would fail later with a message about diverging flows.
fn check_sigma(sigma: Option<f64>, data: &Measurements, file: &Path) -> crate::Result<()> {
    let (Some(sigma), m) = (sigma, data.task_dim) else { return Ok(()) };
    let n = data.len();
    if n == 0 || m == 0 {
        return Ok(());
    }
    let mean: Vec<f64> = (0..m).map(|c| (0..n).map(|i| data.position(i)[c]).sum::<f64>() / n as f64).collect();
    let spread =
        ((0..n).map(|i| data.position(i).iter().zip(&mean).map(|(p, c)| (p - c) * (p - c)).sum::<f64>()).sum::<f64>() / n as f64).sqrt();
    if spread > 0.0 && sigma > MAX_SIGMA_PER_EXTENT * spread {
        return Err(crate::Error::InvalidInput(format!(
            "--sigma {} is over {MAX_SIGMA_PER_EXTENT} × the spread of {}'s positions (RMS {} from their mean): a noise that size would swamp every measurement; give σ in the data's length unit",
            crate::error::as_written(sigma),
            file.display(),
            crate::error::number(spread)
        )));
    }
    Ok(())
}

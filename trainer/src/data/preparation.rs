//! The rows a fit takes, made ready once before any fit (issue 52): the nominal model checked
//! against every row read, at most the rows asked for (evenly spaced through the file), and a
//! given σ checked against their spread. The fit then only calibrates.
//!
//! The nominal model's check ([`nominal_warnings`], also run by `compare` and `diagnose`): one
//! whose positions are not finite is an error naming the row; one that barely moves, or whose
//! positions are far outside the measured ones (a DH length of −1e30, planar lengths [0, 0], a
//! unit mistake), is fitted anyway but with a warning saying so — CbD only corrects small
//! deformations.

use super::csv_import::ImportedMeasurements;
use super::Measurements;
use crate::limits::MAX_MAGNITUDE;
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

/// The nominal model's RMS distance from the measurements above this many times the
/// measurements' own size is not a calibration error but a wrong model, unit or column.
const FAR_FACTOR: f64 = 10.0;

/// The nominal model's RMS distance from the measurements above this fraction of their extent
/// (bounding-box diagonal) is a frame or model mistake, not a calibration error (those are a few
/// per cent at most: the RR demo's 10 % link errors give 3 %, the UR5 example 0.2 %).
const FAR_FROM_EXTENT: f64 = 0.1;

/// A nominal model whose positions span less than this fraction of the measurements' extent
/// does not move with its joints (zero link lengths).
const STILL_FRACTION: f64 = 1e-6;

/// Warnings about `nominal` on `data` (rows at file `lines` of `file`), or an error when the
/// nominal positions are not finite or beyond [`MAX_MAGNITUDE`].
/// `registered`: the base was registered on the data (`base = { register = true }`), so a far
/// nominal is not a frame the registration could fix, and the warning does not suggest it.
pub fn nominal_warnings(
    nominal: &NominalModel,
    data: &Measurements,
    lines: &[u64],
    file: &Path,
    registered: bool,
) -> crate::Result<Vec<String>> {
    let m = data.task_dim;
    let mut predicted = Measurements::new(data.n_joints, m);
    let mut squared = 0.0;
    for i in 0..data.len() {
        let p = &crate::nominal::row_kinematics(nominal, data.joints(i), i).position[..m];
        if let Some(v) = p.iter().find(|v| !(v.abs() <= MAX_MAGNITUDE)) {
            let line = lines.get(i).copied().unwrap_or(0);
            let message = format!(
                "the nominal model's position at this configuration is {v:e} (beyond ±{MAX_MAGNITUDE:e}): its lengths or effects are out of range"
            );
            return Err(crate::Error::NominalAtRow { file: file.to_path_buf(), line, message });
        }
        squared += p.iter().zip(data.position(i)).map(|(a, b)| (a - b) * (a - b)).sum::<f64>();
        predicted.push(data.joints(i), p);
    }
    let rms = (squared / data.len().max(1) as f64).sqrt();
    let measured_extent = data.bounding_box_diagonal();
    let measured_size = data.positions.iter().fold(measured_extent, |s, v| s.max(v.abs()));
    let nominal_extent = predicted.bounding_box_diagonal();
    let mut warnings = Vec::new();
    if data.len() > 1 && measured_extent > 0.0 && nominal_extent <= STILL_FRACTION * measured_extent {
        warnings.push(format!(
            "{}: the nominal model barely moves: its positions span {nominal_extent:.3e} over these configurations, the measurements {measured_extent:.3e} (zero link lengths?); CbD corrects small deformations, not a missing model",
            file.display()
        ));
    }
    if rms > FAR_FACTOR * measured_size {
        warnings.push(format!(
            "{}: the nominal model is {rms:.3e} from the measurements (RMS), more than {FAR_FACTOR} times their size {measured_size:.3e}: wrong unit, DH table or columns?",
            file.display()
        ));
    } else if measured_extent > STILL_FRACTION * measured_size && rms > FAR_FROM_EXTENT * measured_extent {
        // (Rows with no extent — one row, or the same position repeated — have no scale to hold
        // the distance against: no "inf %" alarm; the size check above still applies.)
        // Suggest only what exists for this model: a planar file has no `register`.
        let remedy = match (registered, nominal) {
            (true, _) => "the base is registered already, so not a frame: wrong DH table, joint columns or joint map?",
            (false, NominalModel::PlanarChain { .. }) => "measurements in another frame? declare `base` and `yaw` in [planar]",
            (false, _) => "measurements in a tracker's frame? declare the base, or `base = { register = true }` in [chain] to register it",
        };
        warnings.push(format!(
            "{}: the nominal model is {rms:.3e} from the measurements (RMS), {:.0} % of their extent {measured_extent:.3e}: more than a calibration error — {remedy}",
            file.display(),
            100.0 * rms / measured_extent
        ));
    }
    Ok(warnings)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rr_data() -> (Measurements, Vec<u64>) {
        let real = NominalModel::planar(&[1.0, 0.5]).unwrap();
        let mut data = Measurements::new(2, 2);
        for i in 0..16 {
            let q = [0.4 * i as f64 - 3.0, 0.3 * i as f64 - 2.0];
            data.push(&q, &cbd_runtime::internals::kinematics::forward_kinematics(&real, &q).position[..2]);
        }
        (data, (2..18).collect())
    }

    /// Issue 51 class 4: one row, or rows at one position, have no extent: no "inf %" alarm.
    #[test]
    fn rows_without_extent_raise_no_extent_alarm() {
        let (data, lines) = rr_data();
        let file = Path::new("t.csv");
        let sound = NominalModel::planar(&[1.05, 0.48]).unwrap();
        let mut same = Measurements::new(2, 2);
        for _ in 0..3 {
            same.push(data.joints(0), data.position(0));
        }
        let mut one = Measurements::new(2, 2);
        one.push(data.joints(1), data.position(1));
        for rows in [&same, &one] {
            let w = nominal_warnings(&sound, rows, &lines, file, false).unwrap();
            assert!(w.iter().all(|w| !w.contains("inf") && !w.contains("% of their extent")), "{w:?}");
        }
    }

    /// Issue 17 item 6: absurd nominal models (a length of −1e30; lengths [0, 0]) were fitted with
    /// exit 0 and no warning.
    #[test]
    fn absurd_nominal_models_are_warned_about() {
        let (data, lines) = rr_data();
        let file = Path::new("t.csv");
        let sound = NominalModel::planar(&[1.05, 0.48]).unwrap();
        assert!(nominal_warnings(&sound, &data, &lines, file, false).unwrap().is_empty());
        let still = NominalModel::planar(&[0.0, 0.0]).unwrap();
        let w = nominal_warnings(&still, &data, &lines, file, false).unwrap();
        assert!(w.iter().any(|w| w.contains("barely moves")), "{w:?}");
        let huge = NominalModel::planar(&[-1e30, 0.5]).unwrap();
        let w = nominal_warnings(&huge, &data, &lines, file, false).unwrap();
        assert!(w.iter().any(|w| w.starts_with("t.csv: the nominal model is 1.") && w.contains("wrong unit")), "{w:?}");
        let beyond = NominalModel::planar(&[1e150, 0.5]).unwrap();
        let e = nominal_warnings(&beyond, &data, &lines, file, false).unwrap_err().to_string();
        assert!(e.starts_with("t.csv:2: the nominal model's position"), "{e}");
    }

    /// Issue 39 case 7: the warning suggested `register = true` where it was set, and to planar
    /// files, which refuse it.
    #[test]
    fn the_far_warning_suggests_only_what_applies() {
        let (data, lines) = rr_data();
        let far = NominalModel::planar(&[1.3, 0.9]).unwrap();
        let w = nominal_warnings(&far, &data, &lines, Path::new("t.csv"), false).unwrap().join("\n");
        assert!(w.contains("declare `base` and `yaw` in [planar]") && !w.contains("register"), "{w}");
        let w = nominal_warnings(&far, &data, &lines, Path::new("t.csv"), true).unwrap().join("\n");
        assert!(w.contains("the base is registered already") && !w.contains("register = true"), "{w}");
    }
}

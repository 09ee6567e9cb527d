//! The parametric fit: every DH parameter plus base and tool (its rotation too when tool points lie
//! off its origin), fitted to measured positions.

use super::identifiable::out_of_plane_parameters;
use super::least_squares::{minimise, Minimum};
use super::residuals::residuals;
use super::{DhCalibration, DhCalibrationError, DhCalibrationOptions, DhFitStats};
use crate::data::Measurements;
use crate::nominal::dh_parameters::{apply_parameters, parameter_count_for, parameter_names_for};
use cbd_protocol::{DhChain, NominalModel};

fn rms(r: &[f64], m: usize) -> f64 {
    let n = r.len() / m;
    (r.iter().map(|v| v * v).sum::<f64>() / n.max(1) as f64).sqrt()
}

/// An unidentifiable direction as its large components, largest first: `+0.71·d1 -0.71·d2`.
fn describe_direction(v: &[f64], names: &[String]) -> String {
    let mut parts: Vec<(f64, &str)> = v.iter().zip(names).filter(|(w, _)| w.abs() > 0.3).map(|(w, s)| (*w, s.as_str())).collect();
    parts.sort_by(|a, b| b.0.abs().total_cmp(&a.0.abs()));
    parts.iter().map(|(w, s)| format!("{w:+.2}·{s}")).collect::<Vec<_>>().join(" ")
}

/// The same chain with its θ offsets and α in (−π, π].
fn with_wrapped_angles(mut chain: DhChain) -> DhChain {
    for j in chain.joints.iter_mut() {
        j.theta_offset = j.theta_offset.sin().atan2(j.theta_offset.cos());
        j.alpha = j.alpha.sin().atan2(j.alpha.cos());
    }
    chain
}

/// Fits all DH parameters plus base and tool to `data` (positions in the model's length unit).
/// A planar arm is fitted as its DH form (`nominal::planar::as_dh`) on its two task coordinates,
/// over the parameters that move the tool in the plane (link lengths, joint offsets, base x, y
/// and yaw) when `options.planar_as_dh`; the returned model is then that DH form, read in its
/// first two coordinates.
pub fn calibrate_dh(
    nominal: &NominalModel,
    data: &Measurements,
    options: &DhCalibrationOptions,
) -> Result<DhCalibration, DhCalibrationError> {
    if !options.planar_as_dh && !matches!(nominal, NominalModel::DhChain(_)) {
        return Err(DhCalibrationError::NotADhChain);
    }
    let dh_form = crate::nominal::planar::as_dh(nominal);
    let NominalModel::DhChain(chain0) = &dh_form else { return Err(DhCalibrationError::NotADhChain) };
    let n = chain0.joints.len();
    let np = parameter_count_for(chain0);
    let m = nominal.task_dim();
    let rows = m * data.len();
    if data.len() < 2 || data.task_dim != m {
        return Err(DhCalibrationError::TooFewMeasurements { rows: data.len() });
    }
    let out_of_plane = out_of_plane_parameters(n, m);
    let names = parameter_names_for(chain0);
    let mut r = vec![0.0; rows];
    residuals(chain0, data, &mut r);
    let initial_rms = rms(&r, m);
    let Minimum { p, r, iterations, converged, rank, null_dirs, redundant_at_nominal } = minimise(chain0, data, &out_of_plane, options, r)?;
    let unidentifiable = null_dirs.iter().map(|v| describe_direction(v, &names)).collect();
    let redundant_at_nominal = redundant_at_nominal.iter().map(|&k| names[k].clone()).collect();
    Ok(DhCalibration {
        model: NominalModel::DhChain(with_wrapped_angles(apply_parameters(chain0, &p))),
        stats: DhFitStats {
            iterations,
            initial_rms,
            final_rms: rms(&r, m),
            n_parameters: np - out_of_plane.len(),
            rank,
            unidentifiable,
            parameter_changes: p,
            parameter_names: names,
            converged,
            redundant_at_nominal,
        },
    })
}

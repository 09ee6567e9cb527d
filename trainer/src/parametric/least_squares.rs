//! Levenberg–Marquardt on the SVD of the column-scaled Jacobian J D⁻¹ = U Σ Vᵀ: the damped step
//! (σ_k² + μ)⁻¹ σ_k uₖᵀ r over the directions with σ_k² ≥ rank_tolerance · σ_max², in two stages
//! (the parameters redundant at the nominal model first held fixed, then all freed).

use super::identifiable::redundant_in_plane;
use super::jacobian::{column_scales, jacobian_at, zero_columns};
use super::residuals::residuals;
use super::{DhCalibrationError, DhCalibrationOptions};
use crate::data::Measurements;
use crate::nominal::dh_parameters::{apply_parameters, parameter_count_for};
use crate::solver::least_squares::TruncatedSvd;
use cbd_protocol::DhChain;
use faer::Mat;

/// The unidentifiable directions worth reporting: directions of the out-of-plane parameters alone
/// are not news, only those that move an in-plane parameter are.
fn reported_null_directions(factored: &TruncatedSvd, rank_tolerance: f64, out_of_plane: &[usize]) -> Vec<Vec<f64>> {
    (0..factored.scales().len())
        .filter(|&k| !factored.keeps(k, rank_tolerance))
        .map(|k| factored.direction(k))
        .filter(|v| v.iter().enumerate().any(|(i, w)| w.abs() > 0.3 && !out_of_plane.contains(&i)))
        .collect()
}

/// What the Levenberg–Marquardt iterations of [`super::calibrate_dh`] end with.
pub(super) struct Minimum {
    /// Parameter changes from the nominal, and the residuals there.
    pub p: Vec<f64>,
    pub r: Vec<f64>,
    pub iterations: usize,
    pub converged: bool,
    /// Rank of the last scaled Jacobian and its reported unidentifiable directions.
    pub rank: usize,
    pub null_dirs: Vec<Vec<f64>>,
    /// The parameters held fixed in stage 1.
    pub redundant_at_nominal: Vec<usize>,
}

/// Levenberg–Marquardt on the scaled Jacobian's SVD from the nominal `chain0` (residuals `r`
/// there), the `out_of_plane` parameters fixed.
pub(super) fn minimise(
    chain0: &DhChain,
    data: &Measurements,
    out_of_plane: &[usize],
    options: &DhCalibrationOptions,
    mut r: Vec<f64>,
) -> Result<Minimum, DhCalibrationError> {
    let (rows, np) = (r.len(), parameter_count_for(chain0));
    let mut p = vec![0.0; np];
    let mut cost = 0.5 * r.iter().map(|v| v * v).sum::<f64>();
    let mut mu = -1.0;
    let mut nu = 2.0;
    let mut converged = false;
    let mut iterations = 0;
    let (mut rp, mut rm) = (vec![0.0; rows], vec![0.0; rows]);
    let mut rank = np;
    let mut null_dirs: Vec<Vec<f64>> = Vec::new();
    let mut jac = Mat::<f64>::zeros(rows, np);
    let mut recompute = true;
    let mut frozen: Option<Vec<usize>> = None;
    // Stage 1 keeps the parameters redundant at the nominal fixed (well conditioned, fast);
    // stage 2 ("polish") frees them all, since away from the nominal some become identifiable.
    let mut redundant_at_nominal: Vec<usize> = Vec::new();
    let polish = |frozen: &mut Option<Vec<usize>>, recompute: &mut bool, mu: &mut f64| -> bool {
        match frozen {
            Some(f) if !f.is_empty() => {
                f.clear();
                *recompute = true;
                *mu = -1.0;
                true
            }
            _ => false,
        }
    };
    let mut colnorm = vec![1.0; np];
    let mut svd: Option<TruncatedSvd> = None;
    while iterations < options.max_iterations {
        if recompute {
            jacobian_at(chain0, &p, data, &mut jac, (&mut rp, &mut rm));
            zero_columns(&mut jac, out_of_plane);
            column_scales(&jac, &mut colnorm);
            if frozen.is_none() {
                redundant_at_nominal = redundant_in_plane(&jac, &colnorm, options.redundancy_tolerance, out_of_plane);
                frozen = Some(redundant_at_nominal.clone());
            }
            let still = frozen.as_deref().unwrap_or(&[]);
            zero_columns(&mut jac, still);
            for &k in still {
                colnorm[k] = 1.0;
            }
            // The scaled Jacobian J D⁻¹ = U Σ Vᵀ: λ_k = σ_k² are the eigenvalues of D⁻¹ JᵀJ D⁻¹.
            let factored = TruncatedSvd::with_scales(jac.as_ref(), colnorm.clone())?;
            rank = (0..np).filter(|&k| factored.keeps(k, options.rank_tolerance)).count();
            null_dirs = reported_null_directions(&factored, options.rank_tolerance, out_of_plane);
            if mu < 0.0 {
                mu = 1e-3 * factored.eigenvalues().first().copied().unwrap_or(0.0);
            }
            svd = Some(factored);
            recompute = false;
        }
        let factored = svd.as_ref().expect("computed");
        let lmax = factored.eigenvalues().first().copied().unwrap_or(0.0);
        // Step in scaled parameters over the identifiable directions, and the decrease the linear model predicts.
        let (mut step_s, predicted) = factored.damped_step(&r, mu, options.rank_tolerance);
        // Rounding in the singular vectors must not move what stays out of the plane.
        for &k in out_of_plane {
            step_s[k] = 0.0;
        }
        iterations += 1;
        let step_norm = step_s.iter().map(|v| v * v).sum::<f64>().sqrt();
        let p_norm = p.iter().zip(&colnorm).map(|(v, c)| (v * c).powi(2)).sum::<f64>().sqrt();
        if step_norm <= 1e-14 * (p_norm + 1e-9) || predicted <= 0.0 {
            if polish(&mut frozen, &mut recompute, &mut mu) {
                continue;
            }
            converged = true;
            break;
        }
        let trial: Vec<f64> = p.iter().zip(&step_s).zip(&colnorm).map(|((v, s), c)| v + s / c).collect();
        let mut rt = vec![0.0; rows];
        residuals(&apply_parameters(chain0, &trial), data, &mut rt);
        let new_cost = 0.5 * rt.iter().map(|v| v * v).sum::<f64>();
        let rho = (cost - new_cost) / predicted;
        if new_cost.is_finite() && rho > 0.0 {
            let decrease = cost - new_cost;
            p = trial;
            r = rt;
            cost = new_cost;
            mu *= (1.0f64 / 3.0).max(1.0 - (2.0 * rho - 1.0).powi(3));
            nu = 2.0;
            recompute = true;
            if decrease <= options.cost_tolerance * cost.max(f64::MIN_POSITIVE) || cost == 0.0 {
                if cost > 0.0 && polish(&mut frozen, &mut recompute, &mut mu) {
                    continue;
                }
                converged = true;
                break;
            }
        } else {
            mu *= nu;
            nu *= 2.0;
            if mu > 1e20 * lmax.max(1e-300) {
                if polish(&mut frozen, &mut recompute, &mut mu) {
                    continue;
                }
                converged = true;
                break;
            }
        }
    }
    Ok(Minimum { p, r, iterations, converged, rank, null_dirs, redundant_at_nominal })
}

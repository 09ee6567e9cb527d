//! Gauss–Newton refinement of the selected parameters on the full nonlinear augmented model,
//! min_θ Σ_i |y_i − k(θ; q_i)|², with step halving, and their uncertainties from the
//! Gauss–Newton covariance σ̂² (JᵀJ)⁻¹, σ̂² = SSE / (observations − parameters).

use super::library::{apply, jacobian, predict, Param};
use crate::data::Measurements;
use cbd_protocol::NominalModel;
use faer::{Mat, Side};

/// The refined model and parameters.
#[derive(Debug, Clone)]
pub struct Refined {
    pub model: NominalModel,
    pub values: Vec<f64>,
    /// One standard deviation of each value.
    pub std_errors: Vec<f64>,
    pub sse: f64,
    pub iterations: usize,
}

fn residual(model: &NominalModel, data: &Measurements) -> Vec<f64> {
    predict(model, &data.joints).iter().zip(&data.positions).map(|(k, y)| y - k).collect()
}

/// Scaled normal equations through the eigendecomposition: the step (pseudo-inverse,
/// directions below 1e-12 λ_max dropped) and the diagonal of (JᵀJ)⁺.
fn normal_solve(jac: &Mat<f64>, r: &[f64]) -> (Vec<f64>, Vec<f64>) {
    let p = jac.ncols();
    let scale: Vec<f64> =
        (0..p).map(|k| (0..jac.nrows()).map(|i| jac[(i, k)].powi(2)).sum::<f64>().sqrt().max(f64::MIN_POSITIVE)).collect();
    let js = Mat::from_fn(jac.nrows(), p, |i, k| jac[(i, k)] / scale[k]);
    let g = js.transpose() * &js;
    let rv = Mat::from_fn(r.len(), 1, |i, _| r[i]);
    let b = js.transpose() * &rv;
    let (mut step, mut var) = (vec![0.0; p], vec![0.0; p]);
    let Ok(evd) = g.self_adjoint_eigen(Side::Lower) else { return (step, vec![f64::NAN; p]) };
    let lmax = (0..p).map(|k| evd.S()[k]).fold(0.0, f64::max);
    for k in 0..p {
        let l = evd.S()[k];
        if l <= 1e-12 * lmax || l <= 0.0 {
            continue;
        }
        let u = evd.U();
        let c = (0..p).map(|i| u[(i, k)] * b[(i, 0)]).sum::<f64>() / l;
        for i in 0..p {
            step[i] += c * u[(i, k)];
            var[i] += u[(i, k)] * u[(i, k)] / l;
        }
    }
    (step.iter().zip(&scale).map(|(s, c)| s / c).collect(), var.iter().zip(&scale).map(|(v, c)| v / (c * c)).collect())
}

/// Refines `start` values of `params` on `base` (parameters are changes to `base`).
pub fn refine(base: &NominalModel, data: &Measurements, params: &[Param], start: &[f64], max_iterations: usize) -> Result<Refined, String> {
    let mut values = start.to_vec();
    let mut model = apply(base, params, &values)?;
    let mut r = residual(&model, data);
    let mut sse: f64 = r.iter().map(|v| v * v).sum();
    let mut iterations = 0;
    while iterations < max_iterations && !params.is_empty() {
        iterations += 1;
        let jac = jacobian(&model, data, params);
        let (step, _) = normal_solve(&jac, &r);
        let mut t = 1.0;
        let mut improved = false;
        while t > 1e-4 {
            let trial: Vec<f64> = values.iter().zip(&step).map(|(v, s)| v + t * s).collect();
            let trial_model = apply(base, params, &trial)?;
            let tr = residual(&trial_model, data);
            let trial_sse: f64 = tr.iter().map(|v| v * v).sum();
            if trial_sse.is_finite() && trial_sse <= sse {
                let decrease = sse - trial_sse;
                (values, model, r, sse, improved) = (trial, trial_model, tr, trial_sse, decrease > 1e-12 * sse);
                break;
            }
            t *= 0.5;
        }
        if !improved {
            break;
        }
    }
    let jac = jacobian(&model, data, params);
    let (_, var) = normal_solve(&jac, &r);
    let dof = (r.len() as f64 - params.len() as f64).max(1.0);
    let sigma2 = sse / dof;
    let std_errors = var.iter().map(|v| (sigma2 * v).sqrt()).collect();
    Ok(Refined { model, values, std_errors, sse, iterations })
}

//! Gauss–Newton refinement of the selected parameters on the full nonlinear augmented model,
//! min_θ Σ_i |y_i − k(θ; q_i)|², with step halving (the one least-squares driver,
//! `numeric::levenberg_marquardt`), and their uncertainties from the
//! Gauss–Newton covariance σ̂² (JᵀJ)⁻¹, σ̂² = SSE / (observations − parameters).

use super::library::{apply, jacobian, Param};
use crate::data::Measurements;
use crate::numeric::least_squares::TruncatedSvd;
use crate::numeric::levenberg_marquardt as lm;
use cbd_protocol::NominalModel;
use faer::{Mat, Side};

/// The refined model and parameters.
#[derive(Debug, Clone)]
pub struct Refined {
    pub model: NominalModel,
    pub values: Vec<f64>,
    /// One standard deviation of each value.
    pub std_errors: Vec<f64>,
    /// Covariance of the values, σ̂² (JᵀJ)⁺ (p × p, row-major).
    pub covariance: Vec<f64>,
    /// Residual degrees of freedom: observations − parameters.
    pub dof: f64,
    pub sse: f64,
    pub iterations: usize,
}

/// The Gauss–Newton step (truncated least squares, directions with σ² below 1e-12 σ_max² of the
/// unit-scaled Jacobian dropped) and (JᵀJ)⁺ (p × p, row-major).
fn gauss_newton_solve(jac: &Mat<f64>, r: &[f64]) -> (Vec<f64>, Vec<f64>) {
    const TOLERANCE: f64 = 1e-12;
    let p = jac.ncols();
    match TruncatedSvd::unit_columns(jac.as_ref()) {
        Ok(svd) => (svd.solve(r, TOLERANCE), svd.gram_pseudo_inverse(TOLERANCE)),
        Err(_) => (vec![0.0; p], vec![f64::NAN; p * p]),
    }
}

/// The refinement as the least-squares driver sees it: |y − k(θ)|² over the values.
struct Refinement<'a> {
    base: &'a NominalModel,
    data: &'a Measurements,
    params: &'a [Param],
}

impl crate::numeric::levenberg_marquardt::Problem for Refinement<'_> {
    /// The model, its residual y − k and the sum of squares.
    type Eval = (NominalModel, Vec<f64>, f64);
    type Error = super::DiagnoseError;

    fn cost(&self, at: &Self::Eval) -> f64 {
        at.2
    }

    fn propose(&mut self, _x: &[f64], at: &Self::Eval, _damping: f64, _iteration: usize) -> Result<Option<lm::Step>, Self::Error> {
        let jac = jacobian(&at.0, self.data, self.params);
        let (delta, _) = gauss_newton_solve(&jac, &at.1);
        Ok(Some(lm::Step { delta, predicted: None }))
    }

    fn evaluate(&mut self, trial: &[f64], _delta: &[f64]) -> Result<Option<Self::Eval>, Self::Error> {
        let model = apply(self.base, self.params, trial)?;
        let r = self.data.residual_of(&model);
        let sse = r.iter().map(|v| v * v).sum();
        Ok(Some((model, r, sse)))
    }

    fn accepted(&mut self, step: lm::Accepted<'_, Self::Eval>) -> Option<String> {
        (step.decrease <= 1e-12 * step.from.2).then(|| "sum of squares decreased by at most 1e-12 of it".into())
    }
}

/// Refines `start` values of `params` on `base` (parameters are changes to `base`).
pub fn refine(
    base: &NominalModel,
    data: &Measurements,
    params: &[Param],
    start: &[f64],
    max_iterations: usize,
) -> Result<Refined, super::DiagnoseError> {
    let model = apply(base, params, start)?;
    let r = data.residual_of(&model);
    let sse: f64 = r.iter().map(|v| v * v).sum();
    // Gauss–Newton with step halving (t = 1, ½, … while above 1e-4), a step taken when it does not
    // raise the sum of squares, until one lowers it by at most 1e-12 of it or none lowers it.
    let options = lm::Options {
        damping: lm::Damping::Backtracking { shrink: 0.5, shortest: 1e-4 },
        acceptance: lm::Acceptance::NoIncrease,
        counting: lm::Counting::Steps,
        first_iteration: 1,
        max_iterations: if params.is_empty() { 0 } else { max_iterations },
    };
    let mut problem = Refinement { base, data, params };
    let found = lm::minimise(&mut problem, start.to_vec(), (model, r, sse), &options)?;
    let (values, iterations) = (found.x, found.iterations);
    let (model, r, sse) = found.at;
    let jac = jacobian(&model, data, params);
    let (_, var) = gauss_newton_solve(&jac, &r);
    let p = params.len();
    let dof = (r.len() as f64 - p as f64).max(1.0);
    let sigma2 = sse / dof;
    let covariance: Vec<f64> = var.iter().map(|v| sigma2 * v).collect();
    let std_errors = (0..p).map(|k| covariance[k * p + k].sqrt()).collect();
    Ok(Refined { model, values, std_errors, covariance, dof, sse, iterations })
}

impl Refined {
    /// Wald test that the values at `positions` are all zero: F = vᵀ C⁻¹ v / k with (k, dof)
    /// degrees of freedom (C the positions' covariance block, pseudo-inverse); its tail
    /// probability. For one parameter F = (v / SE)², so p ≤ 0.0027 is |v| ≥ 3 SE.
    pub fn wald_p_value(&self, positions: &[usize]) -> f64 {
        let (p, k) = (self.values.len(), positions.len());
        if k == 0 {
            return 1.0;
        }
        let block = Mat::from_fn(k, k, |i, j| self.covariance[positions[i] * p + positions[j]]);
        let Ok(evd) = block.self_adjoint_eigen(Side::Lower) else { return 1.0 };
        let lmax = (0..k).map(|i| evd.S()[i]).fold(0.0, f64::max);
        let (mut w, mut rank) = (0.0, 0usize);
        for i in 0..k {
            let l = evd.S()[i];
            if l > 1e-12 * lmax && l > 0.0 {
                let c: f64 = (0..k).map(|j| evd.U()[(j, i)] * self.values[positions[j]]).sum();
                w += c * c / l;
                rank += 1;
            }
        }
        if rank == 0 || !w.is_finite() {
            return 1.0;
        }
        super::f_test::f_tail(w / rank as f64, rank as f64, self.dof)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn refined(values: Vec<f64>, covariance: Vec<f64>, dof: f64) -> Refined {
        let p = values.len();
        let std_errors = (0..p).map(|k| covariance[k * p + k].sqrt()).collect();
        Refined { model: NominalModel::planar(&[1.0]).unwrap(), values, std_errors, covariance, dof, sse: 0.0, iterations: 0 }
    }

    #[test]
    fn wald_test_of_one_parameter_is_the_normal_tail_of_its_z_score() {
        // Many degrees of freedom: F(1, ∞) = z², P(|Z| ≥ 3) = 0.0026998, P(|Z| ≥ 1) = 0.3173.
        let three = refined(vec![3.0, 5.0], vec![1.0, 0.0, 0.0, 4.0], 1e7);
        assert!((three.wald_p_value(&[0]) - 0.0026998).abs() < 1e-5, "{}", three.wald_p_value(&[0]));
        let one = refined(vec![2.0], vec![4.0], 1e7);
        assert!((one.wald_p_value(&[0]) - 0.3173).abs() < 1e-3, "{}", one.wald_p_value(&[0]));
    }

    #[test]
    fn wald_test_of_a_group_uses_the_covariance_block() {
        // Two parameters, each 2 SE from zero. Independent: χ²₂ = 8, P = e^{−4} = 0.0183 (the
        // F(2, ∞) tail). Strongly anticorrelated estimates (ρ = −0.99) know their sum 10× better
        // than each: both positive is then jointly far more significant than each alone.
        let independent = refined(vec![2.0, 2.0], vec![1.0, 0.0, 0.0, 1.0], 1e7);
        assert!((independent.wald_p_value(&[0, 1]) - (-4.0f64).exp()).abs() < 1e-4, "{}", independent.wald_p_value(&[0, 1]));
        let correlated = refined(vec![2.0, 2.0], vec![1.0, -0.99, -0.99, 1.0], 1e7);
        assert!(correlated.wald_p_value(&[0, 1]) < 1e-10, "{}", correlated.wald_p_value(&[0, 1]));
        // No parameters: nothing to test.
        assert_eq!(independent.wald_p_value(&[]), 1.0);
    }
}

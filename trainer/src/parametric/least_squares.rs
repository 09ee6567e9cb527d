//! Levenberg–Marquardt on the SVD of the column-scaled Jacobian J D⁻¹ = U Σ Vᵀ: the damped step
//! (σ_k² + μ)⁻¹ σ_k uₖᵀ r over the directions with σ_k² ≥ rank_tolerance · σ_max², in two stages
//! (the parameters redundant at the nominal model first held fixed, then all freed).

use super::identifiable::redundant_in_plane;
use super::jacobian::{column_scales, jacobian_at, zero_columns};
use super::residuals::residuals;
use super::{DhCalibrationError, DhCalibrationOptions};
use crate::data::Measurements;
use crate::nominal::dh_parameters::{apply_parameters, parameter_count_for};
use crate::numeric::least_squares::TruncatedSvd;
use crate::numeric::levenberg_marquardt as lm;
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

/// DH calibration as the least-squares driver sees it: the parameters' changes from the nominal, a
/// point's residuals and ½|r|²; the Jacobian's scaled SVD formed after every accepted step.
struct DhSteps<'a> {
    chain0: &'a DhChain,
    data: &'a Measurements,
    out_of_plane: &'a [usize],
    options: &'a DhCalibrationOptions,
    rp: Vec<f64>,
    rm: Vec<f64>,
    jac: Mat<f64>,
    colnorm: Vec<f64>,
    svd: Option<TruncatedSvd>,
    recompute: bool,
    /// The parameters held fixed: None before the first Jacobian.
    frozen: Option<Vec<usize>>,
    rank: usize,
    null_dirs: Vec<Vec<f64>>,
    redundant_at_nominal: Vec<usize>,
}

impl lm::Problem for DhSteps<'_> {
    type Eval = (Vec<f64>, f64);
    type Error = DhCalibrationError;

    fn cost(&self, at: &Self::Eval) -> f64 {
        at.1
    }

    fn prepare(&mut self, p: &[f64], _at: &Self::Eval) -> Result<(), DhCalibrationError> {
        if !self.recompute {
            return Ok(());
        }
        let (options, out_of_plane) = (self.options, self.out_of_plane);
        jacobian_at(self.chain0, p, self.data, &mut self.jac, (&mut self.rp, &mut self.rm));
        zero_columns(&mut self.jac, out_of_plane);
        column_scales(&self.jac, &mut self.colnorm);
        if self.frozen.is_none() {
            self.redundant_at_nominal = redundant_in_plane(&self.jac, &self.colnorm, options.redundancy_tolerance, out_of_plane);
            self.frozen = Some(self.redundant_at_nominal.clone());
        }
        let still = self.frozen.as_deref().unwrap_or(&[]);
        zero_columns(&mut self.jac, still);
        for &k in still {
            self.colnorm[k] = 1.0;
        }
        // The scaled Jacobian J D⁻¹ = U Σ Vᵀ: λ_k = σ_k² are the eigenvalues of D⁻¹ JᵀJ D⁻¹.
        let factored = TruncatedSvd::with_scales(self.jac.as_ref(), self.colnorm.clone())?;
        self.rank = (0..p.len()).filter(|&k| factored.keeps(k, options.rank_tolerance)).count();
        self.null_dirs = reported_null_directions(&factored, options.rank_tolerance, out_of_plane);
        self.svd = Some(factored);
        self.recompute = false;
        Ok(())
    }

    /// The largest eigenvalue of D⁻¹ JᵀJ D⁻¹.
    fn damping_scale(&self) -> f64 {
        self.svd.as_ref().and_then(|f| f.eigenvalues().first().copied()).unwrap_or(0.0)
    }

    /// The step in scaled parameters over the identifiable directions, and the decrease the linear
    /// model predicts; none once it is negligible or predicts no decrease.
    fn propose(&mut self, p: &[f64], at: &Self::Eval, mu: f64, _iteration: usize) -> Result<Option<lm::Step>, DhCalibrationError> {
        let factored = self.svd.as_ref().expect("computed");
        let (mut step_s, predicted) = factored.damped_step(&at.0, mu, self.options.rank_tolerance);
        // Rounding in the singular vectors must not move what stays out of the plane.
        for &k in self.out_of_plane {
            step_s[k] = 0.0;
        }
        let step_norm = step_s.iter().map(|v| v * v).sum::<f64>().sqrt();
        let p_norm = p.iter().zip(&self.colnorm).map(|(v, c)| (v * c).powi(2)).sum::<f64>().sqrt();
        if step_norm <= 1e-14 * (p_norm + 1e-9) || predicted <= 0.0 {
            return Ok(None);
        }
        let delta = step_s.iter().zip(&self.colnorm).map(|(s, c)| s / c).collect();
        Ok(Some(lm::Step { delta, predicted: Some(predicted) }))
    }

    fn evaluate(&mut self, trial: &[f64], _delta: &[f64]) -> Result<Option<Self::Eval>, DhCalibrationError> {
        let mut rt = vec![0.0; self.rp.len()];
        residuals(&apply_parameters(self.chain0, trial), self.data, &mut rt);
        let cost = 0.5 * rt.iter().map(|v| v * v).sum::<f64>();
        Ok(Some((rt, cost)))
    }

    fn accepted(&mut self, step: lm::Accepted<'_, Self::Eval>) -> Option<String> {
        self.recompute = true;
        let cost = step.to.1;
        (step.decrease <= self.options.cost_tolerance * cost.max(f64::MIN_POSITIVE) || cost == 0.0)
            .then(|| "cost decrease below the tolerance".into())
    }

    /// Stage 2 ("polish"): where stage 1 would stop, the parameters held fixed are freed (away from
    /// the nominal some become identifiable) — not at a zero cost.
    fn restart(&mut self, stop: &lm::Stop, at: &Self::Eval) -> bool {
        if matches!(stop, lm::Stop::Converged(_)) && at.1 <= 0.0 {
            return false;
        }
        match &mut self.frozen {
            Some(f) if !f.is_empty() => {
                f.clear();
                self.recompute = true;
                true
            }
            _ => false,
        }
    }
}

/// Levenberg–Marquardt (the one least-squares driver, `numeric::levenberg_marquardt`, with Nielsen's
/// damping) on the scaled Jacobian's SVD from the nominal `chain0` (residuals `r` there), the
/// `out_of_plane` parameters fixed. Stage 1 keeps the parameters redundant at the nominal fixed
/// (well conditioned, fast); stage 2 frees them all.
pub(super) fn minimise(
    chain0: &DhChain,
    data: &Measurements,
    out_of_plane: &[usize],
    options: &DhCalibrationOptions,
    r: Vec<f64>,
) -> Result<Minimum, DhCalibrationError> {
    let (rows, np) = (r.len(), parameter_count_for(chain0));
    let cost = 0.5 * r.iter().map(|v| v * v).sum::<f64>();
    let mut steps = DhSteps {
        chain0,
        data,
        out_of_plane,
        options,
        rp: vec![0.0; rows],
        rm: vec![0.0; rows],
        jac: Mat::<f64>::zeros(rows, np),
        colnorm: vec![1.0; np],
        svd: None,
        recompute: true,
        frozen: None,
        rank: np,
        null_dirs: Vec::new(),
        redundant_at_nominal: Vec::new(),
    };
    let driver = lm::Options {
        damping: lm::Damping::Nielsen { initial: 1e-3, limit: 1e20 },
        acceptance: lm::Acceptance::Decrease,
        counting: lm::Counting::Trials,
        first_iteration: 1,
        max_iterations: options.max_iterations,
    };
    let found = lm::minimise(&mut steps, vec![0.0; np], (r, cost), &driver)?;
    Ok(Minimum {
        p: found.x,
        r: found.at.0,
        iterations: found.iterations,
        converged: found.stop != lm::Stop::IterationLimit,
        rank: steps.rank,
        null_dirs: steps.null_dirs,
        redundant_at_nominal: steps.redundant_at_nominal,
    })
}

//! The kernel-ridge peer's evidence on every row, in weight space (docs/DESIGN.md §9; issue 38 item 5),
//! as CbD's evidence does (`crate::evidence::weight_space`): its GP with unit amplitude, C = K_V + ν I
//! (ν = σ²/γ, γ profiled out), written in the periodic kernel's truncated expansion,
//! K_V(q, q') ≈ Σ_f λ_f φ_f(q) φ_f(q'), so one design matrix A (N × r, A_if = φ_f(q_i)) serves the m
//! coordinates and an evaluation costs O(r³ + N r m) instead of the kernel form's O(N³).
//!
//! The basis is fixed for a box around the subset's choice (b_d up to 3 ×, ν down to 1/9, i.e. σ
//! down to 1/3 at fixed γ; the dropped prior share 100 × below ν there) and moves when the optimum
//! reaches one of its faces (`crate::evidence::weight_space::minimise_in_boxes`).

mod likelihood;

use crate::data::Measurements;
use crate::evidence::weight_space::design::periodic_design;
use crate::evidence::weight_space::{minimise_in_boxes, BoxedCriterion, Declined, BOX};
use crate::expansion::basis::{truncate, AxisSeries};
use crate::expansion::tolerance_for;
use crate::numeric::FIXED_SPLIT;
use cbd_protocol::NominalModel;
use faer::linalg::matmul::matmul;
use faer::{Accum, Mat};
use std::cell::RefCell;

/// L-BFGS iterations per box (as CbD's weight-space refinement, `EvidenceOptions::max_iterations`).
const MAX_ITERATIONS: u64 = 80;

/// What the refinement on every row was (the peer's JSON `weight_space`).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct KrrWeightSpaceReport {
    /// Periodic functions r of the truncated joint kernel (shared by the m coordinates).
    pub weights: usize,
    /// Prior share the expansion drops (at the box's narrowest kernels and smallest ν).
    pub tolerance: f64,
    /// Boxes used (1 unless the optimum reached a face).
    pub rounds: usize,
    /// Weight-space evaluations (each O(r³ + N r m)).
    pub evaluations: usize,
    /// Wall time of the refinement (its bases, Gram matrices and search).
    pub seconds: f64,
    /// The kernel form's search ran on `kernel_rows` evenly spaced rows and gave the start.
    pub kernel_rows: usize,
    /// Its log marginal likelihood there (on those rows).
    pub kernel_log_marginal_likelihood: f64,
}

/// The residual GP's data in a fixed truncated periodic basis, every row.
pub(crate) struct ResidualWeightSpace {
    n: usize,
    m: usize,
    count: usize,
    /// Per function, its order h per axis (r × n).
    orders: Vec<usize>,
    /// A (N × r).
    design: Mat<f64>,
    /// AᵀA (r × r).
    gram: Mat<f64>,
    /// AᵀR (r × m).
    projection: Mat<f64>,
    /// R (N × m), normalised units.
    residual: Mat<f64>,
    box_lower: Vec<f64>,
    box_upper: Vec<f64>,
    tolerance: f64,
}

impl ResidualWeightSpace {
    /// The table for the box around `packed` = (ln b_1 … ln b_n, ln ν), for the residual `residual`
    /// (N × m) of `data`, or why not: a prismatic joint (its functions would depend on its width), or
    /// more than `max_weights` functions.
    pub(crate) fn new(
        nominal: &NominalModel,
        data: &Measurements,
        residual: &Mat<f64>,
        packed: &[f64],
        max_weights: usize,
    ) -> Result<Self, Declined> {
        let (n, m, count) = (data.n_joints, data.task_dim, data.len());
        Declined::unless_revolute(nominal, n)?;
        // Unit amplitude: the dropped share τ is prior variance relative to γ, and ν = σ²/γ.
        let tolerance = tolerance_for(packed[n].exp().sqrt() / BOX, 1.0);
        let b_max: Vec<f64> = packed[..n].iter().map(|lb| lb.exp() * BOX).collect();
        let axes: Vec<AxisSeries> = b_max.iter().map(|&b| AxisSeries::periodic(b)).collect();
        let basis = truncate(&axes, tolerance).ok_or(Declined::JointOrders { tolerance })?;
        if basis.len() > max_weights {
            return Err(Declined::TooManyWeights { weights: basis.len(), tolerance, limit: max_weights });
        }
        let design = periodic_design(&basis.codes, data);
        let r = basis.len();
        let mut gram = Mat::zeros(r, r);
        matmul(gram.as_mut(), Accum::Replace, design.transpose(), design.as_ref(), 1.0, FIXED_SPLIT);
        let mut projection = Mat::zeros(r, m);
        matmul(projection.as_mut(), Accum::Replace, design.transpose(), residual.as_ref(), 1.0, FIXED_SPLIT);
        // The box: narrower kernels and smaller ν than it covers would need more functions.
        let mut box_lower = vec![f64::NEG_INFINITY; n + 1];
        let mut box_upper = vec![f64::INFINITY; n + 1];
        for (d, b) in b_max.iter().enumerate() {
            box_upper[d] = b.ln();
        }
        box_lower[n] = packed[n] - 2.0 * BOX.ln();
        Ok(ResidualWeightSpace {
            n,
            m,
            count,
            orders: basis.codes.iter().map(|c| (c >> 1) as usize).collect(),
            design,
            gram,
            projection,
            residual: residual.clone(),
            box_lower,
            box_upper,
            tolerance,
        })
    }

    /// Functions r.
    pub(crate) fn weights(&self) -> usize {
        self.gram.nrows()
    }
}

impl BoxedCriterion for ResidualWeightSpace {
    fn box_bounds(&self) -> (&[f64], &[f64]) {
        (&self.box_lower, &self.box_upper)
    }
}

/// The refined choice: (ln b_d, ln ν) packed, the profiled negative log marginal likelihood on every
/// row there, and γ̂.
pub(crate) struct Refined {
    pub param: Vec<f64>,
    pub nlml: f64,
    pub gamma: f64,
    pub report: KrrWeightSpaceReport,
}

/// The subset's choice `start` (ln b_d, ln ν) refined on every row of `data` (`residual` its N × m
/// normalised residual) in weight space, inside the search bounds (`lower`, `upper`) and the basis's
/// box; or why the weight space cannot serve (the caller keeps the subset's choice).
#[allow(clippy::too_many_arguments)]
pub(crate) fn refine(
    nominal: &NominalModel,
    data: &Measurements,
    residual: &Mat<f64>,
    start: &[f64],
    lower: &[f64],
    upper: &[f64],
    max_weights: usize,
    kernel: (usize, f64),
) -> Result<Refined, Declined> {
    let start_time = std::time::Instant::now();
    let evaluations = RefCell::new(0);
    let build = |p: &[f64]| ResidualWeightSpace::new(nominal, data, residual, p, max_weights);
    let found = minimise_in_boxes(build, start, lower, upper, MAX_ITERATIONS, &evaluations)?;
    let (nlml, gamma) = found.table.profiled(&found.param).map(|p| (p.nlml, p.gamma)).ok_or(Declined::NotPositiveDefinite)?;
    let report = KrrWeightSpaceReport {
        weights: found.table.weights(),
        tolerance: found.table.tolerance,
        rounds: found.rounds,
        evaluations: evaluations.into_inner(),
        seconds: start_time.elapsed().as_secs_f64(),
        kernel_rows: kernel.0,
        kernel_log_marginal_likelihood: kernel.1,
    };
    Ok(Refined { param: found.param, nlml, gamma, report })
}

#[cfg(test)]
mod tests;

//! CbD's evidence in weight space (docs/DESIGN.md §3, §11; issue 25): the same linearised model,
//! r = A w + e with w ~ N(0, Λ) and e ~ N(0, σ² I), the kernels written in their own truncated
//! expansions (`crate::expansion`). Its log evidence costs O(N m r²) for r weights instead of the
//! kernel form's O((N m)³), so the search uses every row where the kernel form takes a subset.
//!
//! The joint basis of periodic axes does not depend on θ (b_d and γ_V only set the prior variances
//! Λ), so its Gram matrix is formed once; the task basis depends on the width a and is formed per
//! evaluation, m times cheaper than a dense column since each task weight acts on one coordinate.
//! The basis is fixed for a box of θ around the kernel form's choice (narrower kernels need more
//! functions) and the search stays in that box; an optimum on a face of it moves the box
//! ([`minimise_in_boxes`], shared with the kernel-ridge peer's weight-space search).

pub(crate) mod design;
mod likelihood;
pub(crate) mod prior;

use super::table::Theta;
use super::EvidenceOptions;
use crate::data::Measurements;
use crate::evidence::search::{minimise, Criterion};
use crate::expansion::basis::{truncate, AxisSeries};
use crate::expansion::{task_radius_of, tolerance_for};
use crate::numeric::FIXED_SPLIT;
use cbd_protocol::{NominalModel, Normalisation, TaskKernel};
use faer::linalg::matmul::matmul;
use faer::{Accum, Mat};
use std::cell::RefCell;

/// What the weight-space evidence was (the JSON's `evidence.weight_space`).
#[derive(Debug, Clone, serde::Serialize)]
pub struct WeightSpaceReport {
    /// Weights r of the truncated model: joint functions × n + task functions × m.
    pub weights: usize,
    pub joint_functions: usize,
    pub task_functions: usize,
    /// Prior share each kernel's expansion drops (at the box's narrowest kernels and smallest σ).
    pub tolerance: f64,
    /// Boxes used (1 unless the optimum reached a face).
    pub rounds: usize,
    /// The kernel form's search, on `kernel_rows` evenly spaced rows, gave the start.
    pub kernel_rows: usize,
}

/// The linearised model's data in a fixed truncated basis, for every row.
pub(crate) struct WeightSpaceTable {
    pub(super) n: usize,
    pub(super) m: usize,
    pub(super) count: usize,
    /// Per joint function, its order h per axis (r_J × n).
    pub(super) joint_orders: Vec<usize>,
    pub(super) joint_functions: usize,
    /// Per coordinate c: N × (r_J n), column f n + e = Dk0_i[c][e] φ_f(q_i) (unscaled by Λ).
    pub(super) joint_columns: Vec<Mat<f64>>,
    /// Σ_c A_cᵀ A_c.
    pub(super) joint_gram: Mat<f64>,
    /// Σ_c A_cᵀ r_c.
    pub(super) joint_residual: Vec<f64>,
    /// Task exponents α (r_T × m) and |α|.
    pub(super) task_exponents: Vec<u8>,
    pub(super) task_degrees: Vec<f64>,
    /// Per row k0_i (N × m) and |k0_i|², normalised units.
    pub(super) nominal: Vec<f64>,
    pub(super) radius2: Vec<f64>,
    /// Per coordinate c: the residual r_c (N × 1), shifted to the nominal's with a geometric group.
    pub(super) residual: Vec<Mat<f64>>,
    /// Per coordinate c: the geometric group's explicit columns G_c (N × p; p = 0 without one),
    /// prior-scaled: their weights are N(0, I), fixed in θ.
    pub(super) explicit: Vec<Mat<f64>>,
    /// Σ_c G_cᵀ G_c, Σ_c G_cᵀ A_c (p × r_J n) and Σ_c G_cᵀ r_c: the fixed blocks of the explicit columns.
    pub(super) explicit_gram: Mat<f64>,
    pub(super) explicit_joint: Mat<f64>,
    pub(super) explicit_residual: Vec<f64>,
    /// Packed θ bounds of the box the basis covers (±∞ where it imposes none).
    box_lower: Vec<f64>,
    box_upper: Vec<f64>,
    tolerance: f64,
}

/// Why the weight space does not refine the subset's choice (the search keeps it; the reason is
/// reported as `weight_space_declined`).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum Declined {
    /// `joint` (1-based) is prismatic.
    #[error("joint {joint} is prismatic: its kernel's basis depends on its width")]
    Prismatic { joint: usize },
    #[error("the joint kernel needs orders above 63 at tolerance {tolerance:.0e}")]
    JointOrders { tolerance: f64 },
    #[error("the task kernel needs orders above 63 at tolerance {tolerance:.0e}")]
    TaskOrders { tolerance: f64 },
    #[error("{weights} weights at tolerance {tolerance:.0e} (limit {limit})")]
    TooManyWeights { weights: usize, tolerance: f64, limit: usize },
    #[error("no θ in the basis's box gave a positive-definite system")]
    NotPositiveDefinite,
}

impl Declined {
    /// [`Declined::Prismatic`] for the first of the `n` joints that is not revolute.
    pub(crate) fn unless_revolute(nominal: &NominalModel, n: usize) -> Result<(), Declined> {
        (0..n).find(|&d| !nominal.is_revolute(d)).map_or(Ok(()), |d| Err(Declined::Prismatic { joint: d + 1 }))
    }
}

impl WeightSpaceTable {
    /// The table for the box around `theta` (packed, normalised units), or why not: a prismatic
    /// joint (its basis would depend on its width), or more than `max_weights` weights.
    pub(crate) fn new(
        nominal: &NominalModel,
        data: &Measurements,
        norm: &Normalisation,
        geometry: Option<&super::GeometricBasis>,
        theta: &[f64],
        max_weights: usize,
    ) -> Result<Self, Declined> {
        let (n, m, count) = (data.n_joints, data.task_dim, data.len());
        Declined::unless_revolute(nominal, n)?;
        let theta = Theta::unpack(theta, n);
        let kin: Vec<_> = (0..count).map(|i| crate::nominal::row_kinematics(nominal, data.joints(i), i).normalised(norm)).collect();
        let nominal_positions: Vec<f64> = kin.iter().flat_map(|k| k.position[..m].to_vec()).collect();
        let (gv, gw, sigma) = (theta.log_gamma_v.exp(), theta.log_gamma_w.exp(), theta.log_sigma.exp());
        let mean_j2 = kin.iter().map(|k| (0..m).map(|c| k.jacobian[c][..n].iter().map(|v| v * v).sum::<f64>()).sum::<f64>()).sum::<f64>()
            / (count * m).max(1) as f64;
        let tolerance = tolerance_for(sigma / BOX, gw + gv * mean_j2);
        let b_max: Vec<f64> = theta.log_widths.iter().map(|lb| lb.exp() * BOX).collect();
        let a_min = theta.log_a.exp() / BOX.sqrt();
        let joint_axes: Vec<AxisSeries> = b_max.iter().map(|&b| AxisSeries::periodic(b)).collect();
        let joint = truncate(&joint_axes, tolerance).ok_or(Declined::JointOrders { tolerance })?;
        let task_axes = vec![AxisSeries::gaussian(task_radius_of(&nominal_positions, m) / a_min); m];
        let task = truncate(&task_axes, tolerance).ok_or(Declined::TaskOrders { tolerance })?;
        let weights = joint.len() * n + task.len() * m;
        if weights > max_weights {
            return Err(Declined::TooManyWeights { weights, tolerance, limit: max_weights });
        }
        // Joint columns: Dk0_i[c][e] φ_f(q_i), the periodic functions through the runtime's basis.
        let r_j = joint.len();
        let phi = design::periodic_design(&joint.codes, data);
        let mut joint_columns: Vec<Mat<f64>> = (0..m).map(|_| Mat::zeros(count, r_j * n)).collect();
        for (i, k) in kin.iter().enumerate() {
            for f in 0..r_j {
                for (c, a) in joint_columns.iter_mut().enumerate() {
                    for e in 0..n {
                        a[(i, f * n + e)] = k.jacobian[c][e] * phi[(i, f)];
                    }
                }
            }
        }
        let shift = |i: usize, c: usize| geometry.map_or(0.0, |g| g.shift[i * m + c]);
        let residual: Vec<Mat<f64>> = (0..m)
            .map(|c| Mat::from_fn(count, 1, |i, _| norm.position_to_internal(c, data.position(i)[c]) - kin[i].position[c] + shift(i, c)))
            .collect();
        let explicit: Vec<Mat<f64>> = (0..m).map(|c| geometry.map_or_else(|| Mat::zeros(count, 0), |g| g.coordinate(c))).collect();
        let mut joint_gram = Mat::zeros(r_j * n, r_j * n);
        let mut joint_residual = Mat::zeros(r_j * n, 1);
        for (a, r) in joint_columns.iter().zip(&residual) {
            matmul(joint_gram.as_mut(), Accum::Add, a.transpose(), a.as_ref(), 1.0, FIXED_SPLIT);
            matmul(joint_residual.as_mut(), Accum::Add, a.transpose(), r.as_ref(), 1.0, FIXED_SPLIT);
        }
        let p = explicit.first().map_or(0, |g| g.ncols());
        let (mut explicit_gram, mut explicit_joint, mut explicit_residual) = (Mat::zeros(p, p), Mat::zeros(p, r_j * n), Mat::zeros(p, 1));
        for c in 0..m {
            let g = explicit[c].as_ref();
            matmul(explicit_gram.as_mut(), Accum::Add, g.transpose(), g, 1.0, FIXED_SPLIT);
            matmul(explicit_joint.as_mut(), Accum::Add, g.transpose(), joint_columns[c].as_ref(), 1.0, FIXED_SPLIT);
            matmul(explicit_residual.as_mut(), Accum::Add, g.transpose(), residual[c].as_ref(), 1.0, FIXED_SPLIT);
        }
        let joint_orders = joint.codes.iter().map(|c| (c >> 1) as usize).collect();
        let task_exponents = crate::expansion::solve::task_exponents(&task);
        let task_degrees = task_exponents.chunks_exact(m).map(|a| a.iter().map(|&k| k as f64).sum()).collect();
        let radius2 = nominal_positions.chunks_exact(m).map(|y| y.iter().map(|v| v * v).sum()).collect();
        // The box: narrower kernels and smaller σ than it covers would need more functions.
        let mut box_lower = vec![f64::NEG_INFINITY; n + 4];
        let mut box_upper = vec![f64::INFINITY; n + 4];
        for (d, b) in b_max.iter().enumerate() {
            box_upper[d] = b.ln();
        }
        box_lower[n + 1] = a_min.ln();
        box_lower[n + 3] = (sigma / BOX).ln();
        Ok(WeightSpaceTable {
            n,
            m,
            count,
            joint_orders,
            joint_functions: r_j,
            joint_columns,
            joint_gram,
            joint_residual: (0..r_j * n).map(|k| joint_residual[(k, 0)]).collect(),
            task_exponents,
            task_degrees,
            nominal: nominal_positions,
            radius2,
            residual,
            explicit,
            explicit_gram,
            explicit_joint,
            explicit_residual: (0..p).map(|k| explicit_residual[(k, 0)]).collect(),
            box_lower,
            box_upper,
            tolerance,
        })
    }

    pub(super) fn task_functions(&self) -> usize {
        self.task_degrees.len()
    }

    /// Weights r: joint functions × n, then task functions × m (`expansion::solve::design`'s order).
    pub(super) fn weights(&self) -> usize {
        self.joint_functions * self.n + self.task_functions() * self.m
    }

    /// The geometric group's parameters (explicit columns after the weights; 0 without one).
    pub(super) fn explicit_columns(&self) -> usize {
        self.explicit.first().map_or(0, |g| g.ncols())
    }

    /// The task kernel of width a (normalised), as the runtime's basis takes it.
    pub(super) fn task_kernel(a: f64) -> TaskKernel {
        TaskKernel { width: a }
    }
}

/// The kernel form's θ (`start`, packed) refined on every row of `data` in weight space, inside the
/// search bounds (`lower`, `upper`) and the basis's box: (nlml on all rows, θ, report), or why the
/// weight space cannot serve (the caller keeps the kernel form's subset result).
#[allow(clippy::too_many_arguments)]
pub(super) fn refine(
    nominal: &NominalModel,
    data: &Measurements,
    norm: &Normalisation,
    geometry: Option<&super::GeometricBasis>,
    start: &[f64],
    lower: &[f64],
    upper: &[f64],
    options: &EvidenceOptions,
    kernel_rows: usize,
    evaluations: &RefCell<usize>,
) -> Result<(f64, Vec<f64>, WeightSpaceReport), Declined> {
    let build = |param: &[f64]| WeightSpaceTable::new(nominal, data, norm, geometry, param, options.max_weight_space_weights);
    let found = minimise_in_boxes(build, start, lower, upper, options.max_iterations, evaluations)?;
    let table = &found.table;
    let report = WeightSpaceReport {
        weights: table.weights(),
        joint_functions: table.joint_functions,
        task_functions: table.task_functions(),
        tolerance: table.tolerance,
        rounds: found.rounds,
        kernel_rows,
    };
    Ok((found.nlml, found.param, report))
}

impl BoxedCriterion for WeightSpaceTable {
    fn box_bounds(&self) -> (&[f64], &[f64]) {
        (&self.box_lower, &self.box_upper)
    }
}

// The weight-space search inside moving boxes (docs/DESIGN.md §3): a truncated basis covers a box of
// θ around the point it was built at (narrower kernels and smaller σ need more functions); L-BFGS
// stays inside it, and an optimum on one of the box's own faces rebuilds the basis there. Shared by
// CbD's evidence and the kernel-ridge peer's.

/// How far the box reaches from where its basis was built: joint b_d up to BOX × b_d, task width a
/// down to a / √BOX, σ down to σ / BOX (the truncation tolerance follows σ²).
pub(crate) const BOX: f64 = 3.0;
/// Times the box may move after an optimum on one of its faces.
const MAX_ROUNDS: usize = 3;

/// A criterion in a basis fixed for a box of θ.
pub(crate) trait BoxedCriterion: Criterion {
    /// Packed θ bounds of the box the basis covers (±∞ where it imposes none).
    fn box_bounds(&self) -> (&[f64], &[f64]);
}

/// Where L-BFGS stops in weight space, per unknown (as [`Criterion::tolerances`]): absolute, 1e-4 nats
/// of value change and 1e-3 nats per unit of log θ of gradient. The r × r system keeps the value to far
/// better than the kernel form's ±1 nat, and the optimum lies on flat ridges (widths against amplitudes):
/// with the kernel form's 1e-4 nats per unknown (0.8 nats at N m = 8192, 3.3 at 32768) CbD's search
/// stopped at its start or one step after it, up to a nat short (noisy RR, N = 4096).
pub(crate) fn absolute_tolerances(observations: usize) -> (f64, f64) {
    let per_unknown = 1.0 / observations.max(1) as f64;
    (1e-4 * per_unknown, 1e-3 * per_unknown)
}

/// The optimum found, the table (basis) it was found in, and the boxes used.
pub(crate) struct BoxedOptimum<T> {
    pub nlml: f64,
    pub param: Vec<f64>,
    pub table: T,
    pub rounds: usize,
}

/// L-BFGS from `start` inside the search bounds (`lower`, `upper`) and the box of the table `build`
/// makes around it; while the optimum lies on a face the box imposes (not the search's own bounds),
/// the table is rebuilt there (at most [`MAX_ROUNDS`] boxes). Errors: the table's, or no θ in the box
/// gave a positive-definite system.
pub(crate) fn minimise_in_boxes<T: BoxedCriterion>(
    build: impl Fn(&[f64]) -> Result<T, Declined>,
    start: &[f64],
    lower: &[f64],
    upper: &[f64],
    max_iterations: u64,
    evaluations: &RefCell<usize>,
) -> Result<BoxedOptimum<T>, Declined> {
    let mut param = start.to_vec();
    let mut rounds = 0;
    loop {
        rounds += 1;
        let table = build(&param)?;
        let (box_lower, box_upper) = table.box_bounds();
        let lo: Vec<f64> = lower.iter().zip(box_lower).map(|(a, b)| a.max(*b)).collect();
        let hi: Vec<f64> = upper.iter().zip(box_upper).map(|(a, b)| a.min(*b)).collect();
        let (nlml, found) = minimise(&table, &lo, &hi, &param, max_iterations, evaluations).ok_or(Declined::NotPositiveDefinite)?;
        let on_face =
            (0..found.len()).any(|k| (hi[k] < upper[k] && found[k] >= hi[k] - 1e-3) || (lo[k] > lower[k] && found[k] <= lo[k] + 1e-3));
        param = found;
        if !on_face || rounds == MAX_ROUNDS {
            return Ok(BoxedOptimum { nlml, param, table, rounds });
        }
    }
}

#[cfg(test)]
mod tests;

//! Evaluating a loaded model at one configuration, eq. (20): the query's kernel rows (or the
//! expansion's joint basis) once, then the query flow with its tangents
//! ([`crate::flow::query_derivatives`]) through the model's scheme; the result in the user's units.

use crate::error::Error;
use crate::expansion::fields::ExpansionForm;
use crate::flow::configuration_field::{configuration_row_len, write_configuration_rows, ConfigurationForm};
use crate::flow::query_derivatives::{
    kernel_row_len, query_rates, query_tangent_len, write_kernel_rows, write_nominal_hessian, KernelForm,
};
use crate::flow::{Fixed, Shape};
use crate::kernel::{joint_features, FEATURES_PER_JOINT};
use crate::load::Calibrator;
use crate::real::Real;
use cbd_protocol::{JointKernel, TaskKernel, MAX_JOINTS, MAX_JOINTS as NJ, MAX_TASK_DIM, MAX_TASK_DIM as MT};
use nalgebra::{Dyn, MatrixView, SMatrix, U1};

/// The calibrated position and Jacobian at one configuration, in the user's units.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Evaluation {
    pub(crate) position: SMatrix<f64, MAX_TASK_DIM, 1>,
    pub(crate) jacobian: SMatrix<f64, MAX_TASK_DIM, MAX_JOINTS>,
    pub(crate) transported_jacobian: SMatrix<f64, MAX_TASK_DIM, MAX_JOINTS>,
    pub(crate) task_dim: usize,
    pub(crate) n_joints: usize,
    pub(crate) support: f64,
}

impl Evaluation {
    /// k1(ξ): the calibrated position (length `task_dim`).
    pub fn position(&self) -> MatrixView<'_, f64, Dyn, U1, U1, nalgebra::Const<MAX_TASK_DIM>> {
        // task_dim ≤ MAX_TASK_DIM always; the `min` lets the compiler drop nalgebra's bounds assert.
        self.position.generic_view((0, 0), (Dyn(self.task_dim.min(MAX_TASK_DIM)), U1))
    }
    /// Dk1(ξ): the calibrated Jacobian (`task_dim × n_joints`).
    pub fn jacobian(&self) -> MatrixView<'_, f64, Dyn, Dyn, U1, nalgebra::Const<MAX_TASK_DIM>> {
        self.jacobian.generic_view((0, 0), (Dyn(self.task_dim.min(MAX_TASK_DIM)), Dyn(self.n_joints.min(MAX_JOINTS))))
    }
    /// J(1) of eq. (19)/(20), the Jacobian transported along the flow as in the paper. It omits
    /// the D²k·v term, so it differs from [`Evaluation::jacobian`]; kept for comparison.
    pub fn transported_jacobian(&self) -> MatrixView<'_, f64, Dyn, Dyn, U1, nalgebra::Const<MAX_TASK_DIM>> {
        self.transported_jacobian.generic_view((0, 0), (Dyn(self.task_dim), Dyn(self.n_joints)))
    }
    /// Largest K_V(ξ, x_j)/γ over the measured configurations, in (0, 1]: 1 on a measured
    /// configuration, near 0 far from every one (extrapolation).
    pub fn support(&self) -> f64 {
        self.support
    }
    /// Whether the query is far from every measured configuration (`support` below `threshold`).
    pub fn is_extrapolating(&self, threshold: f64) -> bool {
        self.support < threshold
    }
}

/// eq. (20): the calibrated position k1(ξ) and its exact Jacobian Dk1(ξ) at joint
/// configuration `q` (see [`crate::flow::query_derivatives`]); also the paper's transported J(1).
/// For a model with several tool points this is tool point 0 ([`evaluate_point`]).
pub fn evaluate(cal: &mut Calibrator<'_>, q: &[f64]) -> Result<Evaluation, Error> {
    evaluate_query::<true>(cal, q, 0)
}

/// eq. (20) for tool point `j` (`j` < [`cbd_protocol::NominalModel::tool_point_count`]): the
/// query flow started from k0_j(ξ), Dk0_j(ξ) — the same joint field v(ξ) and task field w, so
/// every tool point is carried by the same ψ ∘ · ∘ φ⁻¹ — with its exact Jacobian.
/// `evaluate_point(q, 0)` is [`evaluate`].
pub fn evaluate_point(cal: &mut Calibrator<'_>, q: &[f64], j: usize) -> Result<Evaluation, Error> {
    evaluate_query::<true>(cal, q, j)
}

/// eq. (20) without tangents, cheaper: the calibrated position k1(ξ) and the paper's
/// transported J(1) (eq. 19), which is *not* the exact derivative of k1; both
/// [`Evaluation::jacobian`] and [`Evaluation::transported_jacobian`] hold J(1).
/// The position is bit-identical to [`evaluate`]'s.
pub fn evaluate_transported(cal: &mut Calibrator<'_>, q: &[f64]) -> Result<Evaluation, Error> {
    evaluate_query::<false>(cal, q, 0)
}

/// The expansion's joint basis at ξ into `rows` and the support (out of line, like both integrations:
/// the kernel form's code stays as it was).
#[inline(never)]
#[allow(clippy::too_many_arguments)]
fn expansion_rows<S: Shape>(
    shape: S,
    kernel: &JointKernel,
    codes: &[u8],
    orders: &[u8; NJ],
    q: &[f64],
    fq: &[[Real; FEATURES_PER_JOINT]; NJ],
    features: &[Real],
    rows: &mut [Real],
    hessian: bool,
) -> f64 {
    crate::expansion::basis_functions::write_joint_basis_shaped(shape, kernel, codes, orders, q, rows, hessian);
    crate::real::to_f64(crate::expansion::fields::support(shape, kernel, fq, features))
}

/// The query's integration with the expansion's stage fields (the kernel form's loop, with the
/// stage's weights c, d in place of its samples).
#[inline(never)]
#[allow(clippy::too_many_arguments)]
fn integrate_expansion<S: Shape>(
    shape: S,
    integrator: cbd_protocol::Integrator,
    task_kernel: TaskKernel,
    e: &cbd_protocol::FieldExpansion<'_>,
    task_orders: [u8; MT],
    weights: &[Real],
    rows: &[Real],
    y: &mut [Real],
    scratch: &mut [Real],
) -> Result<(), Error> {
    let (m, n) = (shape.m(), shape.n());
    let stage_len = e.stage_len(n, m);
    let form = ExpansionForm { task_kernel, exponents: e.task_exponents, orders: task_orders, joint_len: e.n_joint_features as usize * n };
    let last = integrator.stage_count().saturating_sub(1);
    crate::integrate::integrate_checked(integrator.method, integrator.steps, y, scratch, Error::Internal, |stage, s, out| {
        let w = weights.get(stage * stage_len..(stage + 1) * stage_len).ok_or(Error::Internal)?;
        query_rates(shape, &form, w, rows, s, out, stage == last).ok_or(Error::Internal)
    })
}

/// The query's integration with the configuration term (docs/DESIGN.md §16): the kernel form's
/// loop over its one stage (Euler × 1, validated; `samples` the initial state's), the task field
/// with the term from the query's configuration rows. Out of line: the kernel form's code stays
/// as it was.
#[inline(never)]
#[allow(clippy::too_many_arguments)]
fn integrate_configuration<S: Shape>(
    shape: S,
    integrator: cbd_protocol::Integrator,
    task_kernel: TaskKernel,
    task_width: Option<f64>,
    samples: &[Real],
    rows: &[Real],
    configuration_rows: &[Real],
    y: &mut [Real],
    scratch: &mut [Real],
) -> Result<(), Error> {
    if integrator.stage_count() != 1 {
        return Err(Error::Internal);
    }
    let form = ConfigurationForm { task_kernel, task_width, rows: configuration_rows };
    crate::integrate::integrate_checked(integrator.method, integrator.steps, y, scratch, Error::Internal, |_, s, out| {
        query_rates(shape, &form, samples, rows, s, out, true).ok_or(Error::Internal)
    })
}

/// eq. (20): the calibrated position k1(ξ) and the paper's transported J(1); with
/// `exact_jacobian`, also the exact Jacobian Dk1(ξ) of the discrete flow (otherwise the
/// Jacobian reported is J(1)). The position's arithmetic is the same either way.
/// `EXACT_JACOBIAN` is a compile-time switch, not an argument: with both `evaluate` and
/// `evaluate_transported` in one firmware (compensation calls both), a run-time flag kept
/// the tangent branches inside the per-point loop and cost the M7 (dp) 6 % and the f32 build
/// 27 % per `evaluate` (RR N = 256 Heun × 5; BENCHMARKS.md "Firmware (QEMU)").
/// `tool_point` is j of [`cbd_protocol::NominalModel::tool_point`]: the query starts from k0_j(ξ),
/// Dk0_j(ξ), D²k0_j(ξ) (the joint field v(ξ) and the task field are the same for every point).
fn evaluate_query<const EXACT_JACOBIAN: bool>(cal: &mut Calibrator<'_>, q: &[f64], tool_point: usize) -> Result<Evaluation, Error> {
    // The common shapes get loops unrolled at compile time; the arithmetic is the same.
    match (cal.dims.m, cal.dims.n) {
        (2, 2) => evaluate_shaped::<_, EXACT_JACOBIAN>(cal, Fixed::<2, 2>, q, tool_point),
        (3, 6) => evaluate_shaped::<_, EXACT_JACOBIAN>(cal, Fixed::<3, 6>, q, tool_point),
        _ => evaluate_shaped::<_, EXACT_JACOBIAN>(cal, cal.dims, q, tool_point),
    }
}

#[inline(always)]
fn evaluate_shaped<S: Shape, const EXACT_JACOBIAN: bool>(
    cal: &mut Calibrator<'_>,
    shape: S,
    q: &[f64],
    tool_point: usize,
) -> Result<Evaluation, Error> {
    let exact_jacobian = EXACT_JACOBIAN;
    let dims = shape.dims();
    let (m, n) = (dims.m, dims.n);
    if q.len() != n {
        return Err(Error::QueryDimension { expected: n, found: q.len() });
    }
    if n == 0 || dims != cal.dims {
        return Err(Error::Internal);
    }
    if let Some(index) = q.iter().position(|v| !v.is_finite()) {
        return Err(Error::NonFiniteQuery { index });
    }
    let count = cal.model.nominal.tool_point_count();
    if tool_point >= count {
        return Err(Error::ToolPoint { index: tool_point, count });
    }
    let n_points = cal.model.n_points as usize;
    // K_V(ξ, x_j) (or the joint basis at ξ), its gradient and Hessian do not change along the
    // flow: once per query. Working space: those rows, then the query state and the
    // integrator's scratch (in storage rather than on the stack: no zeroing of the largest
    // possible state per query).
    let n_rows = cal.model.expansion.as_ref().map_or(n_points, |e| e.n_joint_features as usize);
    let (rows, rest) = cal.work.split_at_mut_checked(n_rows * kernel_row_len(n)).ok_or(Error::Internal)?;
    // With the configuration term (§16): c_j(ξ) and ∇c_j, also once per query (none without it).
    let configuration = cal.model.configuration_kernel.as_ref();
    let configuration_len = configuration.map_or(0, |_| n_points * configuration_row_len(n));
    let (configuration_rows, rest) = rest.split_at_mut_checked(configuration_len).ok_or(Error::Internal)?;
    let mut fq = [[0.0; FEATURES_PER_JOINT]; NJ];
    joint_features(&cal.model.joint_kernel, q, &mut fq);
    if let Some(c) = configuration {
        // The configuration kernel's axes have the joint kernel's form: the same features.
        write_configuration_rows(shape, c, &fq, cal.features, configuration_rows);
    }
    let configuration_rows: &[Real] = configuration_rows;
    // The rows' second derivatives feed only the δJ rates of the stages before the last
    // ([`query_rates`]): with one stage (Euler × 1) nothing reads them.
    let row_hessians = exact_jacobian && cal.model.integrator.stage_count() > 1;
    let support = match &cal.model.expansion {
        None => {
            let flow_kernel = cal.model.joint_kernel.for_flow(cal.model.momentum_law);
            crate::real::to_f64(write_kernel_rows(shape, &flow_kernel, &fq, cal.features, rows, row_hessians))
                / cal.model.joint_kernel.gamma
        }
        Some(e) => {
            expansion_rows(shape, &cal.model.joint_kernel, e.joint_codes, &cal.orders.joint, q, &fq, cal.features, rows, row_hessians)
        }
    };
    let rows: &[Real] = rows;
    let norm = &cal.model.normalisation;
    let mut h0 = [[[0.0; NJ]; NJ]; MT];
    // k0_j, Dk0_j (and D²k0_j): the model itself for a model without tool points (no copy).
    let k0 = crate::kinematics::with_tool_point(&cal.model.nominal, tool_point, |nominal| {
        if exact_jacobian {
            write_nominal_hessian(nominal, q, &mut h0);
        }
        crate::kinematics::forward_kinematics(nominal, q)
    })
    .ok_or(Error::Internal)?
    .normalised(norm);
    let ql = dims.query_len();
    let state_len = if exact_jacobian { query_tangent_len(dims) } else { ql };
    let (y, rest) = rest.split_at_mut_checked(state_len).ok_or(Error::Internal)?;
    let scratch = rest.get_mut(..crate::integrate::scratch_len(state_len)).ok_or(Error::Internal)?;
    // Every value is written before it is read; cleared anyway so that nothing of the previous
    // query can leak into this one.
    y.fill(0.0);
    scratch.fill(0.0);
    {
        let (primal, tangents) = y.split_at_mut_checked(ql).ok_or(Error::Internal)?;
        let (y_k, y_jac) = primal.split_at_mut_checked(m).ok_or(Error::Internal)?;
        for (dst, src) in y_k.iter_mut().zip(k0.position.iter()) {
            *dst = *src as Real;
        }
        for (dst, src) in y_jac.chunks_exact_mut(n.max(1)).zip(k0.jacobian.iter()) {
            for (d, s) in dst.iter_mut().zip(src.iter()) {
                *d = *s as Real;
            }
        }
        // δk_d(0) = ∂_d k0, δJ_d(0)[a][e] = ∂_e ∂_d k0_a (internal units).
        for (d, t) in tangents.chunks_exact_mut(ql.max(1)).enumerate() {
            let (t_k, t_jac) = t.split_at_mut_checked(m).ok_or(Error::Internal)?;
            for (dst, row) in t_k.iter_mut().zip(k0.jacobian.iter()) {
                *dst = row.get(d).copied().unwrap_or(0.0) as Real;
            }
            for (dst_row, h_a) in t_jac.chunks_exact_mut(n.max(1)).zip(h0.iter()) {
                for (dst, h_ae) in dst_row.iter_mut().zip(h_a.iter()) {
                    *dst = norm.length_to_internal_by_reciprocal(h_ae.get(d).copied().unwrap_or(0.0)) as Real;
                }
            }
        }
    }
    let integrator = cal.model.integrator;
    let task_kernel = cal.model.task_kernel;
    // One integration per form, each with its stage data resolved in its closure.
    match &cal.model.expansion {
        None if configuration.is_some() => {
            let task_width = configuration.and_then(|c| c.task_width);
            let samples = cal.trajectory.get(..n_points * dims.sample_len()).ok_or(Error::Internal)?;
            integrate_configuration(shape, integrator, task_kernel, task_width, samples, rows, configuration_rows, y, scratch)?;
        }
        None => {
            let (trajectory, block): (&[Real], usize) = (cal.trajectory, n_points * dims.sample_len());
            let form = KernelForm { task_kernel };
            let last = integrator.stage_count().saturating_sub(1);
            crate::integrate::integrate_checked(integrator.method, integrator.steps, y, scratch, Error::Internal, |stage, s, out| {
                let samples = trajectory.get(stage * block..(stage + 1) * block).ok_or(Error::Internal)?;
                query_rates(shape, &form, samples, rows, s, out, stage == last).ok_or(Error::Internal)
            })?;
        }
        Some(e) => integrate_expansion(shape, integrator, task_kernel, e, cal.orders.task, cal.weights, rows, y, scratch)?,
    }
    let mut out = Evaluation {
        position: nalgebra::SMatrix::zeros(),
        jacobian: nalgebra::SMatrix::zeros(),
        transported_jacobian: nalgebra::SMatrix::zeros(),
        task_dim: m,
        n_joints: n,
        support,
    };
    let (primal, tangents) = y.split_at_checked(ql).ok_or(Error::Internal)?;
    let (y_k, y_jac) = primal.split_at_checked(m).ok_or(Error::Internal)?;
    for (axis, (dst, v)) in out.position.iter_mut().zip(y_k).enumerate() {
        *dst = norm.position_to_user(axis, crate::real::to_f64(*v));
    }
    for (a, y_row) in y_jac.chunks_exact(n.max(1)).enumerate() {
        for (d, v) in y_row.iter().enumerate() {
            if let Some(dst) = out.transported_jacobian.get_mut((a, d)) {
                *dst = norm.length_to_user(crate::real::to_f64(*v));
            }
        }
    }
    if exact_jacobian {
        for (d, t) in tangents.chunks_exact(ql.max(1)).enumerate() {
            for (a, v) in t.iter().take(m).enumerate() {
                if let Some(dst) = out.jacobian.get_mut((a, d)) {
                    *dst = norm.length_to_user(crate::real::to_f64(*v));
                }
            }
        }
    } else {
        out.jacobian = out.transported_jacobian;
    }
    // Over the matrices' storage (slices: nalgebra's strided iterators cost 20 instructions a value).
    let finite =
        out.position.as_slice().iter().chain(out.jacobian.as_slice()).chain(out.transported_jacobian.as_slice()).all(|v| v.is_finite());
    if finite {
        Ok(out)
    } else {
        Err(Error::NonFiniteResult)
    }
}

#[cfg(test)]
mod configuration_tests;

//! Pose compensation (issue 26 item 1): the joint command q that puts the calibrated tool frame
//! ([`Calibrator::evaluate_pose`]) at a target position and orientation, for arms of at least six
//! joints and models whose tool points determine an orientation. Position-only compensation
//! ([`crate::compensate`]) is unchanged.
//!
//! The start is the pose form of the inverse flows (docs/DESIGN.md §10), k1⁻¹ = φ ∘ k0⁻¹ ∘ ψ⁻¹: the
//! target's tool points y*_j = R* p_j + t* pulled back by ψ⁻¹, the nominal tool frame fitted to
//! them, the nominal pose inverse kinematics of that frame (the closed form of a UR-type arm, the
//! solution nearest the seed; otherwise damped Gauss–Newton on k0's tool frame from the seed), then
//! φ. From there, a fixed number of damped minimum-norm Gauss–Newton steps on the 6-D pose error
//!
//! ```text
//! e = [t* − t(q);  L · log(R* R(q)ᵀ)],   J = [J_v; L · J_ω],   Δq = Jᵀ (J Jᵀ + λ² I)⁻¹ e
//! ```
//!
//! with L the tool points' RMS lever about their centroid (so an angle weighs as the displacement
//! it causes at the points), λ² as in [`crate::inverse_kinematics::damped_min_norm_direction`] and
//! the revolute step bound of [`crate::inverse_kinematics::bounded_step`]. Fixed cost, no heap, no panic.

use crate::compensate::reach_tolerance;
use crate::error::Error;
use crate::flow::inverse::Direction;
use crate::flow_maps::{joint_flow, task_flow};
use crate::inverse_kinematics::{bounded_step, ur};
use crate::kinematics::spatial::{dot, sub, Frame, V3, ZERO};
use crate::kinematics::tool_frame::{determines_orientation, fit_frame, relative_rotation, rotate, rotation_vector};
use crate::kinematics::tool_point::nominal_tool_frame;
use crate::load::Calibrator;
use crate::pose::evaluate_pose;
use cbd_protocol::{NominalModel, MAX_JOINTS as NJ, MAX_TOOL_POINTS};
use nalgebra::{SMatrix, SVector};

/// Fewest joints a pose target needs (three for the position, three for the orientation).
pub const MIN_POSE_JOINTS: usize = 6;

/// Largest deviation of a target rotation from orthonormality, max |R Rᵀ − I|, accepted.
pub const ROTATION_TOLERANCE: f64 = 1e-6;

/// Settings of [`Calibrator::compensate_pose_with`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoseCompensateOptions {
    /// Start from the pose form of the inverse flows instead of the seed itself.
    pub inverse_flow_start: bool,
    /// Gauss–Newton steps on the calibrated pose, each after an [`Calibrator::evaluate_pose`]
    /// (m_p evaluations with the exact Jacobian); one more evaluation judges the last step.
    pub iterations: usize,
    /// Gauss–Newton steps on the nominal tool frame inside the start when the nominal model has no
    /// closed form (k0 only: cheap beside k1).
    pub nominal_iterations: usize,
    /// Largest |t(q) − t*| (user units) counted as reached.
    pub position_tolerance: f64,
    /// Largest orientation error |log(R* R(q)ᵀ)| (radians) counted as reached.
    pub angle_tolerance: f64,
    /// Kernel support below which the command is flagged outside the calibrated region.
    pub extrapolation_threshold: f64,
    /// Conditioning of the weighted 6 × n pose Jacobian below which the command is flagged singular
    /// (geometric over arithmetic mean of the eigenvalues of J Jᵀ, about (σ_min/σ_max)^{1/3}).
    pub singular_conditioning: f64,
}

impl PoseCompensateOptions {
    /// The inverse-flow start, six Gauss–Newton steps (sixteen on the nominal model inside the
    /// start), the position tolerance of position-only compensation
    /// ([`reach_tolerance`]: 1e-9 of the task scale or the model's own precision) and the angle
    /// it subtends at the tool points' lever, extrapolation below support 0.05, singular below
    /// conditioning 1e-3 (σ_min/σ_max below about 1e-9, as position-only compensation's 1e-6 with
    /// its three rows).
    pub fn for_model(cal: &Calibrator<'_>) -> PoseCompensateOptions {
        let position_tolerance = reach_tolerance(cal);
        let lever = tool_lever(&cal.model.nominal);
        PoseCompensateOptions {
            inverse_flow_start: true,
            iterations: 6,
            nominal_iterations: 16,
            position_tolerance,
            angle_tolerance: if lever > 0.0 { position_tolerance / lever } else { 0.0 },
            extrapolation_threshold: 0.05,
            singular_conditioning: 1e-3,
        }
    }
}

/// The outcome of [`Calibrator::compensate_pose`]: the command is in the caller's `out`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoseCompensation {
    /// |t(q) − t*|, the tool frame origin's miss, user units.
    pub position_residual: f64,
    /// |log(R* R(q)ᵀ)|, the orientation's miss, radians.
    pub angle_residual: f64,
    /// Both residuals within their tolerances.
    pub reached: bool,
    /// The weighted pose Jacobian at the command is (nearly) rank-deficient.
    pub singular: bool,
    /// The command is far from every measured configuration.
    pub extrapolating: bool,
    /// Kernel support at the command.
    pub support: f64,
    /// Conditioning of the weighted pose Jacobian at the command.
    pub conditioning: f64,
}

impl PoseCompensation {
    /// Reached, regular and inside the calibrated region.
    pub fn is_ok(&self) -> bool {
        self.reached && !self.singular && !self.extrapolating
    }
}

/// L, the RMS distance of the nominal tool points from their centroid (0 without tool points).
pub fn tool_lever(nominal: &NominalModel) -> f64 {
    let points = nominal.tool_points();
    if points.is_empty() {
        return 0.0;
    }
    let mut c = ZERO;
    for p in points {
        for (ci, pi) in c.iter_mut().zip(p) {
            *ci += pi / points.len() as f64;
        }
    }
    let sum: f64 = points.iter().map(|p| dot(sub(*p, c), sub(*p, c))).sum();
    libm::sqrt(sum / points.len() as f64)
}

/// A pose target: the tool frame's origin and rotation (rows).
#[derive(Debug, Clone, Copy)]
struct Target {
    position: V3,
    rotation: [V3; 3],
}

/// One evaluated pose: origin, rotation, 6 × n Jacobian (unweighted) and support.
struct Pose {
    origin: V3,
    rotation: [V3; 3],
    jacobian: SMatrix<f64, 6, NJ>,
    support: f64,
}

#[derive(Clone, Copy)]
struct Iterate {
    q: SVector<f64, NJ>,
    combined: f64,
    position: f64,
    angle: f64,
    support: f64,
    conditioning: f64,
}

/// e = [t* − t; L · log(R* Rᵀ)] and the weighted Jacobian [J_v; L · J_ω].
fn weighted(target: &Target, pose: &Pose, lever: f64) -> (SVector<f64, 6>, SMatrix<f64, 6, NJ>, f64, f64) {
    let dt = sub(target.position, pose.origin);
    let theta = rotation_vector(&relative_rotation(&target.rotation, &pose.rotation));
    let mut e = SVector::<f64, 6>::zeros();
    for (dst, v) in e.iter_mut().zip(dt.iter().copied().chain(theta.iter().map(|t| t * lever))) {
        *dst = v;
    }
    let mut j = pose.jacobian;
    for r in 3..6 {
        for d in 0..NJ {
            if let Some(v) = j.get_mut((r, d)) {
                *v *= lever;
            }
        }
    }
    (e, j, libm::sqrt(dot(dt, dt)), libm::sqrt(dot(theta, theta)))
}

/// Δq = Jᵀ (J Jᵀ + λ² I)⁻¹ e, λ² = (tr(J Jᵀ)/6) (ρ² + 1e-14), ρ = |e| / scale.
fn damped_pose_direction(j: &SMatrix<f64, 6, NJ>, e: &SVector<f64, 6>, scale: f64) -> Option<SVector<f64, NJ>> {
    let gram = j * j.transpose();
    let mean = gram.trace() / 6.0;
    // The residual relative to the task's size, for the damping (not a unit conversion: the
    // nominal solve takes a bare scale, no offset).
    let rho = e.norm() / scale;
    let mut system = gram;
    for a in 0..6 {
        if let Some(d) = system.get_mut((a, a)) {
            *d += mean * (rho * rho + 1e-14);
        }
    }
    let u = system.cholesky()?.solve(e);
    Some(j.transpose() * u)
}

/// (det G)^{1/6} / (tr G / 6) of G = J Jᵀ, in [0, 1]: about (σ_min/σ_max)^{1/3} when one singular
/// value is small. √det G = Π_a |q_a|, q_a row a of J orthogonalised against the rows before it
/// (Gram–Schmidt, twice: J itself, never G, so an exactly singular J gives ~ε^{1/3}, not √ε^{1/3}).
fn pose_conditioning(j: &SMatrix<f64, 6, NJ>) -> f64 {
    let mean = (j * j.transpose()).trace() / 6.0;
    if !(mean > 0.0) || !mean.is_finite() {
        return 0.0;
    }
    let mut basis = [[0.0f64; NJ]; 6];
    let mut root = 1.0;
    for a in 0..6 {
        let mut v = [0.0f64; NJ];
        for (d, x) in v.iter_mut().enumerate() {
            *x = j.get((a, d)).copied().unwrap_or(0.0);
        }
        for _ in 0..2 {
            for q in basis.iter().take(a) {
                let projection: f64 = v.iter().zip(q.iter()).map(|(x, y)| x * y).sum();
                for (x, y) in v.iter_mut().zip(q.iter()) {
                    *x -= projection * y;
                }
            }
        }
        let norm = libm::sqrt(v.iter().map(|x| x * x).sum::<f64>());
        if !(norm > 0.0) {
            return 0.0;
        }
        // (det G)^{1/6} / mean = Π_a (|q_a| / √mean)^{1/3}, scaled as it accumulates: no overflow.
        root *= libm::cbrt(norm / libm::sqrt(mean));
        if let Some(q) = basis.get_mut(a) {
            for (dst, x) in q.iter_mut().zip(v.iter()) {
                *dst = x / norm;
            }
        }
    }
    root.clamp(0.0, 1.0)
}

/// `iterations` damped Gauss–Newton steps on the pose from `q`; the best iterate.
#[allow(clippy::too_many_arguments)]
fn pose_newton(
    mut evaluate: impl FnMut(&[f64]) -> Result<Pose, Error>,
    mut q: SVector<f64, NJ>,
    n: usize,
    target: &Target,
    lever: f64,
    scale: f64,
    iterations: usize,
    revolute: &[bool; NJ],
) -> Result<Iterate, Error> {
    let mut best = Iterate { q, combined: f64::INFINITY, position: f64::INFINITY, angle: f64::INFINITY, support: 0.0, conditioning: 0.0 };
    for step in 0..=iterations {
        let pose = evaluate(q.as_slice().get(..n).ok_or(Error::Internal)?)?;
        let (e, j, position, angle) = weighted(target, &pose, lever);
        let combined = e.norm();
        if combined < best.combined {
            best = Iterate { q, combined, position, angle, support: pose.support, conditioning: pose_conditioning(&j) };
        }
        if step < iterations {
            let direction = damped_pose_direction(&j, &e, scale);
            if let Some(dq) = direction.and_then(|d| bounded_step(d, |k| revolute.get(k).copied().unwrap_or(true))) {
                q += dq;
            }
        }
    }
    Ok(best)
}

/// The nominal tool frame at `q` as a [`Pose`].
fn nominal_pose(nominal: &NominalModel, q: &[f64]) -> Result<Pose, Error> {
    let (fit, jac) = nominal_tool_frame(nominal, q).ok_or(Error::NonFiniteResult)?;
    let mut jacobian = SMatrix::<f64, 6, NJ>::zeros();
    for (r, row) in jac.iter().enumerate() {
        for (d, v) in row.iter().enumerate() {
            if let Some(dst) = jacobian.get_mut((r, d)) {
                *dst = *v;
            }
        }
    }
    Ok(Pose { origin: fit.origin, rotation: fit.rotation, jacobian, support: 1.0 })
}

/// [`Calibrator::compensate_pose_with`] with [`PoseCompensateOptions::for_model`].
pub fn compensate_pose(
    cal: &mut Calibrator<'_>,
    position: &[f64],
    rotation: &[[f64; 3]; 3],
    seed: &[f64],
    out: &mut [f64],
) -> Result<PoseCompensation, Error> {
    let options = PoseCompensateOptions::for_model(cal);
    compensate_pose_with(cal, position, rotation, seed, out, &options)
}

/// Writes to `out` the joint command q whose calibrated tool frame ([`Calibrator::evaluate_pose`])
/// has origin `position` and rotation `rotation` (rows, task frame): from the pose form of the
/// inverse flows (`seed` choosing the nominal branch; the seed itself without
/// `options.inverse_flow_start` or when the start fails), `options.iterations` damped
/// Gauss–Newton steps on the 6-D pose error (module doc). The best iterate is returned, with
/// flags instead of an error when the target is not reached.
///
/// Errors: fewer than [`MIN_POSE_JOINTS`] joints ([`Error::TooFewJoints`]), tool points that
/// do not determine an orientation ([`Error::OrientationUndetermined`]), wrong lengths, a
/// non-finite target (index 0–2 the position, 3–11 the rotation's entries by rows) or seed,
/// a rotation that is not one ([`Error::InvalidRotation`], tolerance [`ROTATION_TOLERANCE`]),
/// and the evaluation's own errors.
pub fn compensate_pose_with(
    cal: &mut Calibrator<'_>,
    position: &[f64],
    rotation: &[[f64; 3]; 3],
    seed: &[f64],
    out: &mut [f64],
    options: &PoseCompensateOptions,
) -> Result<PoseCompensation, Error> {
    let n = cal.dims.n;
    let (target, revolute) = checked_pose_query(&cal.model.nominal, position, rotation, seed, out)?;
    let (lever, scale) = (tool_lever(&cal.model.nominal), cal.model.normalisation.task_scale);
    let mut start = [0.0; NJ];
    let start_slice = start.get_mut(..n).ok_or(Error::Internal)?;
    let from_flows = options.inverse_flow_start
        && pose_inverse_flow_start(cal, &target, seed, start_slice, options.nominal_iterations, &revolute).is_ok();
    let mut q = SVector::<f64, NJ>::zeros();
    for (dst, s) in q.iter_mut().zip(if from_flows { start_slice.iter() } else { seed.iter() }) {
        *dst = *s;
    }
    let best = pose_newton(
        |qs| {
            let p = evaluate_pose(cal, qs)?;
            Ok(Pose { origin: p.origin, rotation: p.rotation, jacobian: p.jacobian, support: p.support() })
        },
        q,
        n,
        &target,
        lever,
        scale,
        options.iterations,
        &revolute,
    )?;
    for (dst, v) in out.iter_mut().zip(best.q.iter()) {
        *dst = *v;
    }
    Ok(PoseCompensation {
        position_residual: best.position,
        angle_residual: best.angle,
        reached: best.position.is_finite()
            && best.angle.is_finite()
            && best.position <= options.position_tolerance
            && best.angle <= options.angle_tolerance,
        singular: !(best.conditioning >= options.singular_conditioning),
        extrapolating: !(best.support >= options.extrapolation_threshold),
        support: best.support,
        conditioning: best.conditioning,
    })
}

/// k1⁻¹ = φ ∘ k0⁻¹ ∘ ψ⁻¹ for a pose: ψ⁻¹ of every target tool point, the nominal frame fitted
/// to them, its nominal inverse kinematics from `seed` (UR closed form nearest the seed, or
/// `nominal_iterations` Gauss–Newton steps on k0's tool frame), then φ. Writes `out` (n values).
fn pose_inverse_flow_start(
    cal: &mut Calibrator<'_>,
    target: &Target,
    seed: &[f64],
    out: &mut [f64],
    nominal_iterations: usize,
    revolute: &[bool; NJ],
) -> Result<(), Error> {
    let n = cal.dims.n;
    let count = cal.model.nominal.tool_point_count();
    let mut nominal = [[0.0; 3]; MAX_TOOL_POINTS];
    let mut pulled = [[0.0; 3]; MAX_TOOL_POINTS];
    for (j, (p, z)) in nominal.iter_mut().zip(pulled.iter_mut()).enumerate().take(count) {
        *p = cal.model.nominal.tool_point(j).ok_or(Error::Internal)?;
        // y*_j = R* p_j + t*
        let r = rotate(&target.rotation, *p);
        let y = [r[0] + target.position[0], r[1] + target.position[1], r[2] + target.position[2]];
        task_flow(cal, &y, Direction::Backward, z)?;
    }
    let fit = fit_frame(nominal.get(..count).ok_or(Error::Internal)?, pulled.get(..count).ok_or(Error::Internal)?)
        .ok_or(Error::OrientationUndetermined)?;
    let nominal_target = Target { position: fit.origin, rotation: fit.rotation };
    let scale = cal.model.normalisation.task_scale;
    let q = nominal_pose_solve(&cal.model.nominal, &nominal_target, seed, n, nominal_iterations, revolute, scale)?;
    joint_flow(cal, q.as_slice().get(..n).ok_or(Error::Internal)?, Direction::Forward, out)
}

/// The nominal pose inverse kinematics of `target` from `seed`: the UR closed form's solution
/// nearest the seed, or `iterations` damped Gauss–Newton steps on k0's tool frame ([`pose_newton`]).
fn nominal_pose_solve(
    nominal: &NominalModel,
    target: &Target,
    seed: &[f64],
    n: usize,
    iterations: usize,
    revolute: &[bool; NJ],
    scale: f64,
) -> Result<SVector<f64, NJ>, Error> {
    let mut q = SVector::<f64, NJ>::zeros();
    for (dst, s) in q.iter_mut().zip(seed.iter()) {
        *dst = *s;
    }
    let closed = match (nominal, seed.first_chunk::<6>()) {
        (NominalModel::DhChain(chain), Some(hint)) if ur::is_ur_type(chain) => {
            ur::nearest_solution(ur::solutions(chain, &Frame::new(target.rotation, target.position)), hint)
        }
        _ => None,
    };
    match closed {
        Some(closed) => {
            for (dst, c) in q.iter_mut().zip(closed.iter()) {
                *dst = *c;
            }
            Ok(q)
        }
        None => Ok(pose_newton(|qs| nominal_pose(nominal, qs), q, n, target, tool_lever(nominal), scale, iterations, revolute)?.q),
    }
}

/// Writes to `out` the joints whose nominal tool frame (`kinematics::tool_point::nominal_tool_frame`)
/// has origin `position` and rotation `rotation` (rows): the nominal half of
/// [`Calibrator::compensate_pose`]'s start — the UR closed form's solution nearest `seed`, or
/// `iterations` damped Gauss–Newton steps on the 6-D pose error from `seed` (`scale`: the task
/// scale of the damping, ρ = |e| / scale). Returns the miss (|t(q) − t*|, |log(R* R(q)ᵀ)| radians).
/// Errors as [`Calibrator::compensate_pose_with`]'s (joints, orientation, target, seed).
pub fn nominal_pose_inverse(
    nominal: &NominalModel,
    position: &[f64],
    rotation: &[[f64; 3]; 3],
    seed: &[f64],
    out: &mut [f64],
    iterations: usize,
    scale: f64,
) -> Result<(f64, f64), Error> {
    let n = nominal.n_joints();
    let (target, revolute) = checked_pose_query(nominal, position, rotation, seed, out)?;
    let q = nominal_pose_solve(nominal, &target, seed, n, iterations, &revolute, scale)?;
    for (dst, v) in out.iter_mut().zip(q.iter()) {
        *dst = *v;
    }
    // The miss at the command, as the Gauss–Newton iterates are judged.
    let (_, _, position_miss, angle_miss) = weighted(&target, &nominal_pose(nominal, out)?, tool_lever(nominal));
    Ok((position_miss, angle_miss))
}

/// The target checked: finite, a rotation (max |R Rᵀ − I| ≤ [`ROTATION_TOLERANCE`], det > 0).
fn validated_target(position: &[f64], rotation: &[[f64; 3]; 3]) -> Result<Target, Error> {
    let Some(&[x, y, z]) = position.first_chunk::<3>().filter(|_| position.len() == 3) else {
        return Err(Error::TargetDimension { expected: 3, found: position.len() });
    };
    if let Some(index) = [x, y, z].iter().chain(rotation.iter().flatten()).position(|v| !v.is_finite()) {
        return Err(Error::NonFiniteTarget { index });
    }
    let rrt = relative_rotation(rotation, rotation);
    let mut deviation: f64 = 0.0;
    for (i, row) in rrt.iter().enumerate() {
        for (j, v) in row.iter().enumerate() {
            deviation = deviation.max(libm::fabs(v - if i == j { 1.0 } else { 0.0 }));
        }
    }
    let [r0, r1, r2] = *rotation;
    let det = dot(r0, crate::kinematics::spatial::cross(r1, r2));
    if !(deviation <= ROTATION_TOLERANCE) || !(det > 0.0) {
        return Err(Error::InvalidRotation);
    }
    Ok(Target { position: [x, y, z], rotation: *rotation })
}

/// The checks every pose query makes (errors as documented on [`Calibrator::compensate_pose_with`]):
/// the validated target and which of `nominal`'s joints are revolute.
fn checked_pose_query(
    nominal: &NominalModel,
    position: &[f64],
    rotation: &[[f64; 3]; 3],
    seed: &[f64],
    out: &[f64],
) -> Result<(Target, [bool; NJ]), Error> {
    let n = nominal.n_joints();
    if n < MIN_POSE_JOINTS {
        return Err(Error::TooFewJoints { found: n, needed: MIN_POSE_JOINTS });
    }
    if !determines_orientation(nominal.tool_points()) {
        return Err(Error::OrientationUndetermined);
    }
    let target = validated_target(position, rotation)?;
    if seed.len() != n || out.len() != n {
        return Err(Error::QueryDimension { expected: n, found: if seed.len() != n { seed.len() } else { out.len() } });
    }
    if let Some(index) = seed.iter().position(|v| !v.is_finite()) {
        return Err(Error::NonFiniteQuery { index });
    }
    if n > NJ {
        return Err(Error::Internal);
    }
    let mut revolute = [true; NJ];
    for (d, r) in revolute.iter_mut().enumerate().take(n) {
        *r = nominal.is_revolute(d);
    }
    Ok((target, revolute))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The nominal pose inverse on a UR-type chain (closed form) and on one that is not (α2 off by
    /// 0.01 rad: Gauss–Newton from the seed): the target frame is reached from a seed 0.05 rad
    /// away; too few joints and points on a line are refused.
    #[test]
    fn the_nominal_pose_inverse_reaches_a_reachable_frame() {
        let points = [[0.0, 0.0, 0.0], [100.0, 0.0, 0.0], [50.0, 86.6, 0.0]];
        let mut ur = cbd_protocol::ur5::chain();
        ur.tool.translation = [0.0, 0.0, 31.0];
        ur.tool_points = heapless::Vec::from_slice(&points).unwrap();
        let mut bent = ur.clone();
        if let Some(j) = bent.joints.get_mut(1) {
            j.alpha += 0.01;
        }
        assert!(ur::is_ur_type(&ur) && !ur::is_ur_type(&bent));
        let q_star = [0.4, -1.1, 1.3, -0.7, 1.2, 0.5];
        let seed: [f64; 6] = core::array::from_fn(|d| q_star[d] + if d % 2 == 0 { 0.05 } else { -0.05 });
        for chain in [ur, bent] {
            let model = NominalModel::DhChain(chain);
            let (frame, _) = nominal_tool_frame(&model, &q_star).unwrap();
            let mut q = [0.0; 6];
            let (position, angle) = nominal_pose_inverse(&model, &frame.origin, &frame.rotation, &seed, &mut q, 16, 500.0).unwrap();
            let (at, _) = nominal_tool_frame(&model, &q).unwrap();
            let miss = libm::sqrt(dot(sub(at.origin, frame.origin), sub(at.origin, frame.origin)));
            assert!(position < 1e-9 && angle < 1e-11 && (miss - position).abs() < 1e-12, "{position} {angle} {miss}");
            for (a, b) in q.iter().zip(q_star) {
                assert!((a - b).abs() < 1e-9, "{q:?} against {q_star:?}");
            }
        }
        let mut line = cbd_protocol::ur5::chain();
        line.tool_points = heapless::Vec::from_slice(&[[0.0, 0.0, 0.0], [100.0, 0.0, 0.0]]).unwrap();
        let id = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
        let mut q = [0.0; 6];
        let refused = nominal_pose_inverse(&NominalModel::DhChain(line), &[0.0; 3], &id, &seed, &mut q, 16, 500.0);
        assert_eq!(refused.err(), Some(Error::OrientationUndetermined));
    }

    #[test]
    fn targets_that_are_not_rotations_are_refused() {
        let id = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
        assert!(validated_target(&[1.0, 2.0, 3.0], &id).is_ok());
        assert_eq!(validated_target(&[1.0, 2.0], &id).err(), Some(Error::TargetDimension { expected: 3, found: 2 }));
        assert_eq!(validated_target(&[1.0, 2.0, 3.0, 4.0], &id).err(), Some(Error::TargetDimension { expected: 3, found: 4 }));
        let mirror = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, -1.0]];
        assert_eq!(validated_target(&[1.0, 2.0, 3.0], &mirror).err(), Some(Error::InvalidRotation));
        let stretched = [[1.0 + 1e-5, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
        assert_eq!(validated_target(&[1.0, 2.0, 3.0], &stretched).err(), Some(Error::InvalidRotation));
        let mut nan = id;
        nan[1][2] = f64::NAN;
        assert_eq!(validated_target(&[1.0, 2.0, 3.0], &nan).err(), Some(Error::NonFiniteTarget { index: 8 }));
    }

    #[test]
    fn the_conditioning_is_the_mean_ratio_of_the_eigenvalues() {
        let mut j = SMatrix::<f64, 6, NJ>::zeros();
        for a in 0..6 {
            j[(a, a)] = 2.0;
        }
        assert!((pose_conditioning(&j) - 1.0).abs() < 1e-15);
        for d in 0..6 {
            for a in 0..6 {
                j[(a, d)] = libm::sin(1.0 + (7 * a + 3 * d) as f64) + if a == d { 3.0 } else { 0.0 };
            }
        }
        let gram = j * j.transpose();
        let expected = libm::pow(gram.determinant(), 1.0 / 6.0) / (gram.trace() / 6.0);
        assert!((pose_conditioning(&j) - expected).abs() < 1e-12 * expected, "{} vs {expected}", pose_conditioning(&j));
        for a in 0..6 {
            j[(a, 5)] = j[(a, 4)];
        }
        // Exactly rank-deficient: rounding leaves ~ε^{1/3}, below the default threshold 1e-3.
        assert!(pose_conditioning(&j) < 1e-4, "{}", pose_conditioning(&j));
        j[(0, 0)] = f64::NAN;
        assert_eq!(pose_conditioning(&j), 0.0);
    }

    #[test]
    fn the_lever_is_the_rms_distance_from_the_centroid() {
        let mut c = cbd_protocol::ur5::chain();
        c.tool_points = heapless::Vec::from_slice(&[[0.0, 0.0, 0.0], [100.0, 0.0, 0.0], [0.0, 100.0, 0.0]]).unwrap();
        let lever = tool_lever(&NominalModel::DhChain(c));
        // Centroid (100/3, 100/3, 0): squared distances 2/9, 5/9, 5/9 × 100².
        assert!((lever - 100.0 * libm::sqrt(12.0 / 27.0)).abs() < 1e-12);
    }
}

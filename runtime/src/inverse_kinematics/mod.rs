//! Inverse kinematics of the nominal model k0 and the damped minimum-norm Gauss–Newton step that
//! [`crate::compensate`] also uses on the calibrated model k1.
//!
//! Closed forms where the nominal model has one ([`planar`]: two-link planar arm, both elbows;
//! [`ur`]: UR-type six-joint arm, the eight solutions); otherwise a fixed number of damped
//! Gauss–Newton steps on k0 from a caller's seed ([`nominal_position`]). No heap, no panic, fixed cost.

pub mod fold;
pub mod planar;
pub mod ur;

use cbd_protocol::{NominalModel, MAX_JOINTS as NJ, MAX_TASK_DIM as MT};
use nalgebra::{SMatrix, SVector};

/// Largest change of a revolute joint in one Gauss–Newton step (radians): keeps a step taken near
/// a singularity, where the linearisation is poor, from throwing the iterate to another branch.
pub const MAX_REVOLUTE_STEP: f64 = 0.5;

/// The damped minimum-norm Gauss–Newton step for J Δq ≈ r (J is m × n, m ≤ 3 rows used):
///
/// ```text
/// Δq = Jᵀ (J Jᵀ + λ² I)⁻¹ r,      λ² = (tr(J Jᵀ)/m) · (ρ² + 1e-14),   ρ = |r| / scale
/// ```
///
/// For n = m and λ → 0 it is Newton's step J⁻¹ r; for n > m it is the minimum-norm solution of
/// J Δq = r, so repeated steps from a seed keep the seed's redundant (orientation) coordinates.
/// The damping shrinks with the residual (Levenberg–Marquardt with λ ∝ |r|, which keeps Newton's
/// quadratic convergence near a regular solution), and its floor keeps the system solvable at an
/// exact singularity. Revolute components are then scaled together so that none exceeds
/// [`MAX_REVOLUTE_STEP`]. `None` when the system is not positive definite (non-finite J or r).
pub fn damped_min_norm_step(
    jacobian: &SMatrix<f64, MT, NJ>,
    residual: &SVector<f64, MT>,
    m: usize,
    scale: f64,
    revolute: impl Fn(usize) -> bool,
) -> Option<SVector<f64, NJ>> {
    bounded_step(damped_min_norm_direction(jacobian, residual, m, scale)?, revolute)
}

/// [`damped_min_norm_step`] before its revolute components are bounded.
pub fn damped_min_norm_direction(
    jacobian: &SMatrix<f64, MT, NJ>,
    residual: &SVector<f64, MT>,
    m: usize,
    scale: f64,
) -> Option<SVector<f64, NJ>> {
    let m = m.clamp(1, MT);
    let gram = jacobian * jacobian.transpose();
    let mean_eigenvalue = gram.trace() / m as f64;
    // The residual relative to the task's size, for the damping (not a unit conversion: the
    // nominal inverse kinematics takes a bare scale, no offset).
    let rho = residual.norm() / scale;
    let damping_sq = mean_eigenvalue * (rho * rho + 1e-14);
    // Rows ≥ m of J are zero: their diagonal gets 1 so the padded system stays definite (their
    // right-hand side is zero, so they contribute nothing to Δq).
    let mut system = gram;
    for a in 0..MT {
        if let Some(diagonal) = system.get_mut((a, a)) {
            *diagonal += if a < m { damping_sq } else { 1.0 };
        }
    }
    let u = system.cholesky()?.solve(residual);
    Some(jacobian.transpose() * u)
}

/// `step` with its revolute components scaled together so that none exceeds
/// [`MAX_REVOLUTE_STEP`]; `None` unless every component is finite.
pub fn bounded_step(mut step: SVector<f64, NJ>, revolute: impl Fn(usize) -> bool) -> Option<SVector<f64, NJ>> {
    let mut largest: f64 = 0.0;
    for (d, s) in step.iter().enumerate() {
        if revolute(d) {
            largest = largest.max(s.abs());
        }
    }
    if largest > MAX_REVOLUTE_STEP {
        step *= MAX_REVOLUTE_STEP / largest;
    }
    if step.iter().all(|v| v.is_finite()) {
        Some(step)
    } else {
        None
    }
}

/// How well conditioned J is, in [0, 1]: the geometric over the arithmetic mean of the eigenvalues
/// of J Jᵀ (the squared singular values), (det G)^{1/m} / (tr G / m). 1 for an isotropic Jacobian,
/// 0 at a singularity (rank < m); about (σ_min/σ_max)^{2/m} when one singular value is small.
pub fn conditioning(jacobian: &SMatrix<f64, MT, NJ>, m: usize) -> f64 {
    let m = m.clamp(1, MT);
    let gram = jacobian * jacobian.transpose();
    let mean = gram.trace() / m as f64;
    if !(mean > 0.0) || !mean.is_finite() {
        return 0.0;
    }
    let g = |a: usize, b: usize| gram.get((a, b)).copied().unwrap_or(0.0);
    let det = match m {
        1 => g(0, 0),
        2 => g(0, 0) * g(1, 1) - g(0, 1) * g(1, 0),
        _ => gram.determinant(),
    };
    let geometric = libm::pow(det.max(0.0), 1.0 / m as f64);
    (geometric / mean).clamp(0.0, 1.0)
}

/// Result of [`nominal_position`]: |k0(q) − target| at the returned q, in the model's units.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NominalSolution {
    /// |k0(q) − target| (model units).
    pub residual: f64,
}

/// Position-only inverse kinematics of k0: `iterations` damped minimum-norm Gauss–Newton steps
/// ([`damped_min_norm_step`]) from `seed`, written to `out`; the iterate with the smallest
/// residual is returned. For a two-link planar arm the seed's elbow's closed form
/// ([`planar::two_link`]) is the start; for a UR-type arm the closed-form solution nearest the
/// seed for the tool orientation the seed has ([`ur::nearest_to_hint`]). `scale` is a length of the arm's size (the residual's
/// damping is relative to it). Fixed cost; `None` for a dimension mismatch or non-finite input.
pub fn nominal_position(
    nominal: &NominalModel,
    target: &[f64],
    seed: &[f64],
    out: &mut [f64],
    iterations: usize,
    scale: f64,
) -> Option<NominalSolution> {
    let (n, m) = (nominal.n_joints(), nominal.task_dim());
    if target.len() != m || seed.len() != n || out.len() != n || n > NJ || m > MT || n == 0 {
        return None;
    }
    if target.iter().chain(seed.iter()).any(|v| !v.is_finite()) || !(scale > 0.0) {
        return None;
    }
    let mut q = SVector::<f64, NJ>::zeros();
    for (dst, s) in q.iter_mut().zip(seed.iter()) {
        *dst = *s;
    }
    if let NominalModel::PlanarChain { lengths, .. } = nominal {
        if let ([l1, l2], [x, y]) = (lengths.as_slice(), target) {
            let elbow =
                if libm::sin(seed.get(1).copied().unwrap_or(0.0)) >= 0.0 { planar::Elbow::Positive } else { planar::Elbow::Negative };
            if let Some(closed) = planar::two_link(*l1, *l2, [*x, *y], elbow) {
                // The same angles modulo 2π as the seed's turns, so that the solution is near it.
                for (dst, (c, s)) in q.iter_mut().zip(closed.iter().zip(seed.iter())) {
                    *dst = c + nearest_turn(*s - c);
                }
            }
        }
    }
    if let (NominalModel::DhChain(chain), [x, y, z]) = (nominal, target) {
        if let (true, Some(hint)) = (ur::is_ur_type(chain), seed.first_chunk::<6>()) {
            if let Some(closed) = ur::nearest_to_hint(chain, &[*x, *y, *z], hint) {
                for (dst, c) in q.iter_mut().zip(closed.iter()) {
                    *dst = *c;
                }
            }
        }
    }
    let target_v = padded_target(target);
    let (mut best_q, mut best_residual) = (q, f64::INFINITY);
    for step in 0..=iterations {
        let qs = q.as_slice().get(..n)?;
        let k0 = crate::kinematics::forward_kinematics(nominal, qs);
        let (position, jacobian) = matrices_of(&k0.position, &k0.jacobian, m, n);
        let r = target_v - position;
        let residual = r.norm();
        if residual < best_residual {
            best_residual = residual;
            best_q = q;
        }
        if step < iterations {
            if let Some(dq) = damped_min_norm_step(&jacobian, &r, m, scale, |d| nominal.is_revolute(d)) {
                q += dq;
            }
        }
    }
    for (dst, v) in out.iter_mut().zip(best_q.iter()) {
        *dst = *v;
    }
    if best_residual.is_finite() {
        Some(NominalSolution { residual: best_residual })
    } else {
        None
    }
}

/// 2π k nearest to `delta`: the whole turns to add to an angle to bring it within π of another.
pub fn nearest_turn(delta: f64) -> f64 {
    let two_pi = 2.0 * core::f64::consts::PI;
    libm::round(delta / two_pi) * two_pi
}

/// The target as a 3-vector (unused rows zero).
pub(crate) fn padded_target(target: &[f64]) -> SVector<f64, MT> {
    let mut v = SVector::<f64, MT>::zeros();
    for (dst, t) in v.iter_mut().zip(target.iter()) {
        *dst = *t;
    }
    v
}

/// Position and Jacobian (row-major arrays, m × n used) as padded nalgebra matrices.
pub(crate) fn matrices_of(
    position: &[f64; MT],
    jacobian: &[[f64; NJ]; MT],
    m: usize,
    n: usize,
) -> (SVector<f64, MT>, SMatrix<f64, MT, NJ>) {
    let mut p = SVector::<f64, MT>::zeros();
    let mut j = SMatrix::<f64, MT, NJ>::zeros();
    for (a, (pa, row)) in position.iter().zip(jacobian.iter()).enumerate().take(m) {
        if let Some(slot) = p.get_mut(a) {
            *slot = *pa;
        }
        for (d, v) in row.iter().enumerate().take(n) {
            if let Some(slot) = j.get_mut((a, d)) {
                *slot = *v;
            }
        }
    }
    (p, j)
}

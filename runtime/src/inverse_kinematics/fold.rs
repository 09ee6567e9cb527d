//! A Gauss–Newton step that knows about folds: where the smallest singular value σ of J is small
//! (the arm almost stretched out or folded, a target near the workspace's boundary), k is modelled
//! as quadratic along that singular direction instead of linear, and the step along it is the
//! nearer root of the quadratic. Newton's linear model there predicts a step of ρ/σ, far past the
//! root, and converges only linearly (halving the distance per step) on a root near the fold;
//! the quadratic model's root is accurate to the error of its curvature. Closed forms, fixed cost,
//! no heap, no panic.

use cbd_protocol::{NominalModel, MAX_JOINTS as NJ, MAX_TASK_DIM as MT};
use nalgebra::{SMatrix, SVector};

/// The smallest singular value σ of J's first `m` rows (m ≤ 3) with its left and right singular
/// vectors u (unit, m entries used) and v = Jᵀ u / σ (unit), from the smallest eigenvalue of the
/// m × m Gram matrix J Jᵀ in closed form (the trigonometric solution of the cubic for m = 3) and
/// its eigenvector from the rows of J Jᵀ − λ I. `None` when J is zero, not finite, or σ is below
/// 1e-12 of J's scale (no direction to speak of: v is then rounding noise).
pub fn smallest_singular_pair(jacobian: &SMatrix<f64, MT, NJ>, m: usize) -> Option<(f64, SVector<f64, MT>, SVector<f64, NJ>)> {
    let m = m.clamp(1, MT);
    let mut j = *jacobian;
    for a in m..MT {
        j.row_mut(a).fill(0.0);
    }
    let gram = j * j.transpose();
    let trace = gram.trace();
    if !(trace > 0.0) || !trace.is_finite() {
        return None;
    }
    let u = smallest_eigenvector(&gram, m)?;
    let jt_u = j.transpose() * u;
    let sigma = jt_u.norm();
    if !(sigma > 1e-12 * libm::sqrt(trace)) || !sigma.is_finite() {
        return None;
    }
    Some((sigma, u, jt_u / sigma))
}

/// Unit eigenvector of the symmetric `gram` (m × m used) for its smallest eigenvalue.
fn smallest_eigenvector(gram: &SMatrix<f64, MT, MT>, m: usize) -> Option<SVector<f64, MT>> {
    let g = |a: usize, b: usize| gram.get((a, b)).copied().unwrap_or(0.0);
    let mut u = SVector::<f64, MT>::zeros();
    match m {
        1 => u.x = 1.0,
        2 => {
            let (a, b, c) = (g(0, 0), g(0, 1), g(1, 1));
            let half = 0.5 * (a - c);
            let lambda = 0.5 * (a + c) - libm::sqrt(half * half + b * b);
            // (G − λI) u = 0: either row gives u ⟂ it; the longer one is the better conditioned.
            let (first, second) = ([b, lambda - a], [lambda - c, b]);
            let pick =
                if first[0] * first[0] + first[1] * first[1] >= second[0] * second[0] + second[1] * second[1] { first } else { second };
            (u.x, u.y) = (pick[0], pick[1]);
        }
        _ => {
            // Smith (1961): eigenvalues q + 2p cos(φ + 2πk/3) of a symmetric 3 × 3 matrix.
            let q = gram.trace() / 3.0;
            let off = g(0, 1) * g(0, 1) + g(0, 2) * g(0, 2) + g(1, 2) * g(1, 2);
            let d = [g(0, 0) - q, g(1, 1) - q, g(2, 2) - q];
            let p = libm::sqrt((d[0] * d[0] + d[1] * d[1] + d[2] * d[2] + 2.0 * off) / 6.0);
            let lambda = if p > 0.0 {
                let b = (gram - SMatrix::<f64, MT, MT>::identity() * q) / p;
                let half_det = (0.5 * b.determinant()).clamp(-1.0, 1.0);
                let phi = libm::acos(half_det) / 3.0;
                q + 2.0 * p * libm::cos(phi + 2.0 * core::f64::consts::PI / 3.0)
            } else {
                q
            };
            let shifted = gram - SMatrix::<f64, MT, MT>::identity() * lambda;
            let rows = [shifted.row(0).transpose(), shifted.row(1).transpose(), shifted.row(2).transpose()];
            let [r0, r1, r2] = rows;
            let candidates = [r0.cross(&r1), r0.cross(&r2), r1.cross(&r2)];
            let mut best = SVector::<f64, MT>::zeros();
            for c in candidates {
                if c.norm_squared() > best.norm_squared() {
                    best = c;
                }
            }
            u = best;
        }
    }
    let norm = u.norm();
    if norm > 0.0 && norm.is_finite() {
        Some(u / norm)
    } else {
        // Isotropic (or a repeated smallest eigenvalue): every such direction is a singular one.
        let mut e = SVector::<f64, MT>::zeros();
        e.x = 1.0;
        Some(e)
    }
}

/// uᵀ D²k0(q)[v, v]: the nominal model's curvature along `v` seen along `u`, by a central
/// difference of its Jacobian (two evaluations of k0, cheap beside one of k1). The calibrated
/// model's k1 = ψ ∘ k0 ∘ φ⁻¹ differs from k0 by a small, smooth deformation, so this stands in for
/// the curvature of k1.
pub fn nominal_curvature(
    nominal: &NominalModel,
    q: &SVector<f64, NJ>,
    u: &SVector<f64, MT>,
    v: &SVector<f64, NJ>,
    m: usize,
    n: usize,
) -> f64 {
    const H: f64 = 1e-4;
    let (mut plus, mut minus) = ([0.0; NJ], [0.0; NJ]);
    for ((p, mi), (qd, vd)) in plus.iter_mut().zip(minus.iter_mut()).zip(q.iter().zip(v.iter())) {
        *p = qd + H * vd;
        *mi = qd - H * vd;
    }
    let (Some(plus), Some(minus)) = (plus.get(..n), minus.get(..n)) else { return f64::NAN };
    let (kp, km) = (crate::kinematics::forward_kinematics(nominal, plus), crate::kinematics::forward_kinematics(nominal, minus));
    let mut curvature = 0.0;
    for ((ua, rp), rm) in u.iter().zip(kp.jacobian.iter()).zip(km.jacobian.iter()).take(m) {
        let mut row = 0.0;
        for ((a, b), vd) in rp.iter().zip(rm.iter()).zip(v.iter()).take(n) {
            row += (a - b) * vd;
        }
        curvature += ua * row;
    }
    curvature / (2.0 * H)
}

/// The step along v of the quadratic model σ t + ½ a t² = ρ (ρ = uᵀ r, the residual along u): its
/// root nearest 0, or the model's vertex −σ/a (the smallest residual along u) when it has no real
/// root (the target beyond the fold by the model). `None` when neither is finite.
pub fn fold_root(sigma: f64, curvature: f64, rho: f64) -> Option<f64> {
    let discriminant = sigma * sigma + 2.0 * curvature * rho;
    let t = if discriminant >= 0.0 {
        let denominator = sigma + libm::sqrt(discriminant);
        if denominator > 0.0 {
            2.0 * rho / denominator
        } else {
            0.0
        }
    } else {
        -sigma / curvature
    };
    if t.is_finite() {
        Some(t)
    } else {
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// σ_min, u and v against the definition J v = σ u, Jᵀ u = σ v, for m = 1, 2, 3 (a Jacobian
    /// with singular values 3, 1e-3 and 2 in rotated bases for m = 3).
    #[test]
    fn the_smallest_singular_pair_satisfies_its_definition() {
        let mut j = SMatrix::<f64, MT, NJ>::zeros();
        (j[(0, 0)], j[(0, 1)], j[(0, 3)]) = (0.3, -1.2, 0.4);
        let (sigma, u, v) = smallest_singular_pair(&j, 1).unwrap();
        assert!((sigma - libm::sqrt(0.09 + 1.44 + 0.16)).abs() < 1e-15 && (u.x.abs() - 1.0).abs() < 1e-15);
        assert!((j * v - u * sigma).norm() < 1e-14);
        for m in [2, 3] {
            let (c, s) = (libm::cos(0.7), libm::sin(0.7));
            let mut left = SMatrix::<f64, MT, MT>::identity();
            (left[(0, 0)], left[(0, 1)], left[(1, 0)], left[(1, 1)]) = (c, -s, s, c);
            let mut right = SMatrix::<f64, NJ, NJ>::identity();
            (right[(1, 1)], right[(1, 2)], right[(2, 1)], right[(2, 2)]) = (c, s, -s, c);
            let mut diag = SMatrix::<f64, MT, NJ>::zeros();
            (diag[(0, 0)], diag[(1, 1)]) = (3.0, 1e-3);
            if m == 3 {
                diag[(2, 2)] = 2.0;
            }
            let j = left * diag * right;
            let (sigma, u, v) = smallest_singular_pair(&j, m).unwrap();
            assert!((sigma - 1e-3).abs() < 1e-12, "m = {m}: σ {sigma}");
            let (e1, e2) = ((j * v - u * sigma).norm(), (j.transpose() * u - v * sigma).norm());
            // J v − σ u = (G u − σ² u) / σ: the Gram matrix's rounding, σ_max² ε / σ ≈ 2e-12.
            assert!(e1 < 1e-11 && e2 < 1e-12, "m = {m}: {e1:e} {e2:e}");
            assert!((u.norm() - 1.0).abs() < 1e-14 && (v.norm() - 1.0).abs() < 1e-14);
        }
        assert!(smallest_singular_pair(&SMatrix::zeros(), 2).is_none());
    }

    #[test]
    fn the_fold_root_is_the_nearer_root_or_the_vertex() {
        // σ t + ½ a t² = ρ with σ = 1, a = 2, ρ = 2: t² + t − 2 = 0, roots 1 and −2.
        assert!((fold_root(1.0, 2.0, 2.0).unwrap() - 1.0).abs() < 1e-15);
        // At the fold (σ = 0): t = ±√(2ρ/a); the step keeps the sign of ρ / a.
        assert!((fold_root(0.0, 2.0, 0.01).unwrap() - 0.1).abs() < 1e-15);
        // No real root (ρ beyond the fold): the vertex −σ/a.
        assert!((fold_root(1.0, -2.0, 1.0).unwrap() - 0.5).abs() < 1e-15);
        // No curvature: Newton's ρ/σ.
        assert!((fold_root(2.0, 0.0, 1.0).unwrap() - 0.5).abs() < 1e-15);
        assert_eq!(fold_root(0.0, 0.0, -1.0), Some(0.0));
    }

    /// The planar 2R arm stretched out along x (q2 = 0): Jacobian rank 1 along the arm, and the
    /// curvature along the null direction (the elbow) seen along the arm is −l2.
    #[test]
    fn the_nominal_curvature_of_a_stretched_planar_arm() {
        let nominal = NominalModel::planar(&[1.0, 0.5]).unwrap();
        let (q, mut u, mut v) = (SVector::<f64, NJ>::zeros(), SVector::<f64, MT>::zeros(), SVector::<f64, NJ>::zeros());
        (u.x, v[1]) = (1.0, 1.0);
        let a = nominal_curvature(&nominal, &q, &u, &v, 2, 2);
        assert!((a + 0.5).abs() < 1e-8, "{a}");
    }
}

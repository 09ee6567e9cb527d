//! Candidate configurations: uniform within the joint limits, and the distance of a configuration
//! to the nearest singular one (docs/DESIGN.md §13).

use crate::nominal::{cross, norm, sub};
use cbd_protocol::NominalModel;
use cbd_runtime::internals::kinematics::forward_kinematics;
use cbd_runtime::internals::kinematics::rigid::dh_walk;
use faer::{Mat, Side};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// The smallest linearised distance to a singular configuration a planned pose may have: 1°.
pub const SINGULAR_MARGIN: f64 = std::f64::consts::PI / 180.0;

/// `count` configurations (row-major) uniform within `limits` (finite `[lo, hi]` per joint).
pub fn uniform_within(limits: &[[f64; 2]], count: usize, seed: u64) -> Vec<f64> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    (0..count).flat_map(|_| limits.iter().map(|[lo, hi]| rng.gen_range(*lo..*hi)).collect::<Vec<_>>()).collect()
}

/// Whether every joint of `q` lies within its `[lo, hi]`.
pub fn within_limits(q: &[f64], limits: &[[f64; 2]]) -> bool {
    q.iter().zip(limits).all(|(v, [lo, hi])| *lo <= *v && *v <= *hi)
}

/// The Jacobian whose rank the arm needs at a pose, rows × n row-major: for a spatial chain of six
/// or more joints the geometric Jacobian (linear part over `reach`, so both parts are per radian),
/// position and orientation; otherwise the position Jacobian (a planar arm, a shorter chain).
pub fn task_jacobian(nominal: &NominalModel, q: &[f64], reach: f64) -> (Vec<f64>, usize) {
    let n = nominal.n_joints();
    match nominal {
        NominalModel::DhChain(chain) if n >= 6 => {
            let walk = dh_walk(chain, q);
            let mut j = vec![0.0; 6 * n];
            for k in 0..n {
                let z = walk.axes[k];
                // J_v = z × (p − o), J_ω = z (revolute); J_v = z, J_ω = 0 (prismatic).
                let (v, w) = if nominal.is_revolute(k) { (cross(z, sub(walk.tool, walk.origins[k])), z) } else { (z, [0.0; 3]) };
                for c in 0..3 {
                    j[c * n + k] = v[c] / reach;
                    j[(3 + c) * n + k] = w[c];
                }
            }
            (j, 6)
        }
        _ => {
            let m = nominal.task_dim();
            let k = forward_kinematics(nominal, q);
            ((0..m).flat_map(|c| (0..n).map(move |d| k.jacobian[c][d] / reach)).collect(), m)
        }
    }
}

/// The smallest of the min(rows, n) singular values of a rows × n matrix (row-major).
fn smallest_singular_value(j: &[f64], rows: usize, n: usize) -> f64 {
    let r = rows.min(n);
    // Gram of the smaller side: J Jᵀ (rows ≤ n) or Jᵀ J; its eigenvalues are the σ².
    let gram = Mat::from_fn(r, r, |a, b| {
        if rows <= n {
            (0..n).map(|d| j[a * n + d] * j[b * n + d]).sum::<f64>()
        } else {
            (0..rows).map(|c| j[c * n + a] * j[c * n + b]).sum::<f64>()
        }
    });
    match gram.self_adjoint_eigenvalues(Side::Lower) {
        Ok(ev) => ev.iter().cloned().fold(f64::INFINITY, f64::min).max(0.0).sqrt(),
        Err(_) => 0.0,
    }
}

/// The linearised joint-space distance (radians, Euclidean) from `q` to the nearest singular
/// configuration: d = s / |∇s|, s the smallest singular value of [`task_jacobian`], its gradient
/// by central differences (step 1e-4 rad). Exact to first order: along −∇s, s reaches 0 after d.
pub fn singular_distance(nominal: &NominalModel, q: &[f64], reach: f64) -> f64 {
    let n = q.len();
    let s_at = |x: &[f64]| {
        let (j, rows) = task_jacobian(nominal, x, reach);
        smallest_singular_value(&j, rows, n)
    };
    let s = s_at(q);
    let h = 1e-4;
    let mut x = q.to_vec();
    let mut g2 = 0.0;
    for d in 0..n {
        x[d] = q[d] + h;
        let up = s_at(&x);
        x[d] = q[d] - h;
        let down = s_at(&x);
        x[d] = q[d];
        g2 += ((up - down) / (2.0 * h)).powi(2);
    }
    if g2 > 0.0 {
        s / g2.sqrt()
    } else if s > 0.0 {
        f64::INFINITY
    } else {
        0.0
    }
}

/// A length scale of the arm on `joints` (row-major): the largest distance of the tool from the
/// base, or 1 for a degenerate chain.
pub fn reach(nominal: &NominalModel, joints: &[f64]) -> f64 {
    let n = nominal.n_joints();
    let r = joints
        .chunks_exact(n)
        .map(|q| {
            let k = forward_kinematics(nominal, q);
            let p = [k.position[0], k.position[1], if nominal.task_dim() > 2 { k.position[2] } else { 0.0 }];
            norm(p)
        })
        .fold(0.0, f64::max);
    if r > 0.0 && r.is_finite() {
        r
    } else {
        1.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn planar_distance_is_the_elbow_angle() {
        let rr = crate::simulate::rr::nominal();
        for q2 in [0.3_f64, 0.05, -0.02, 3.0] {
            let d = singular_distance(&rr, &[0.7, q2], 1.5);
            // The singular set is q2 ∈ {0, π}: the distance to the nearer.
            let truth = q2.abs().min((std::f64::consts::PI - q2).abs());
            assert!((d - truth).abs() < 0.1 * truth + 1e-3, "q2 {q2}: {d} vs {truth}");
        }
    }

    #[test]
    fn uniform_samples_stay_within_limits() {
        let limits = [[-1.0, 2.0], [0.5, 0.6]];
        let q = uniform_within(&limits, 500, 3);
        assert!(q.chunks_exact(2).all(|x| within_limits(x, &limits)));
    }
}

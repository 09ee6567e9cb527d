//! The tool frame from several tool points (issue 26 item 1): the rotation R and origin t that best
//! map the nominal tool points p_j (offsets in the tool frame) onto measured or calibrated points
//! y_j in least squares, min Σ_j |R p_j + t − y_j|², and the frame's velocity (linear velocity of
//! the origin, angular velocity) as a linear function of the points' velocities.
//!
//! Horn's quaternion method: with the centred points p'_j = p_j − p̄, y'_j = y_j − ȳ and
//! S = Σ_j p'_j y'_jᵀ, the rotation is the unit quaternion of the largest eigenvalue of Horn's
//! symmetric 4 × 4 matrix N(S) (cyclic Jacobi sweeps: fixed work bound, deterministic, no heap),
//! and t = ȳ − R p̄. Fewer than 3 points, or points all on one line, leave the rotation about that
//! line undetermined: `None`, never a guess. f64 throughout, no panic path.

use crate::kinematics::spatial::{add_scaled, cross, dot, scale, sub, V3, ZERO};

/// Most Jacobi sweeps (each zeroes the 6 off-diagonal pairs once); a 4 × 4 converges in 4–6.
const MAX_SWEEPS: usize = 24;

/// Below this, Σ_{a<b} λ_a λ_b of the nominal points' scatter, relative to (Σ λ)², the points are
/// taken to lie on one line (a lever of 1e-6 of their spread).
pub const COLLINEAR_TOLERANCE: f64 = 1e-12;

/// A least-squares rigid frame: y ≈ R p + t.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameFit {
    /// R, rows.
    pub rotation: [V3; 3],
    /// t: where the frame puts p = 0 (the tool frame's origin).
    pub origin: V3,
    /// √(Σ_j |R p_j + t − y_j|² / m_p): how far the points are from a rigid copy of the nominal ones.
    pub residual: f64,
}

#[inline(always)]
fn at<const N: usize>(a: &[[f64; N]; N], i: usize, j: usize) -> f64 {
    a.get(i).and_then(|r| r.get(j)).copied().unwrap_or(0.0)
}

#[inline(always)]
fn set<const N: usize>(a: &mut [[f64; N]; N], i: usize, j: usize, v: f64) {
    if let Some(x) = a.get_mut(i).and_then(|r| r.get_mut(j)) {
        *x = v;
    }
}

/// The centroid of `points` (ZERO for none).
fn centroid(points: &[V3]) -> V3 {
    let mut c = ZERO;
    for p in points {
        add_scaled(&mut c, *p, 1.0);
    }
    if points.is_empty() {
        ZERO
    } else {
        scale(c, 1.0 / points.len() as f64)
    }
}

/// Whether `points` determine an orientation: at least 3, not all on one line
/// (Σ_{a<b} λ_a λ_b of their centred scatter C = Σ p' p'ᵀ above [`COLLINEAR_TOLERANCE`] (tr C)²).
pub fn determines_orientation(points: &[V3]) -> bool {
    if points.len() < 3 || points.iter().flatten().any(|v| !v.is_finite()) {
        return false;
    }
    let c = centroid(points);
    let mut scatter = [[0.0; 3]; 3];
    for p in points {
        let d = sub(*p, c);
        for (row, da) in scatter.iter_mut().zip(d) {
            for (s, db) in row.iter_mut().zip(d) {
                *s += da * db;
            }
        }
    }
    let trace = at(&scatter, 0, 0) + at(&scatter, 1, 1) + at(&scatter, 2, 2);
    // Σ_{a<b} λ_a λ_b = ((tr C)² − tr C²) / 2
    let trace_sq: f64 = scatter.iter().flatten().map(|v| v * v).sum();
    let pairs = 0.5 * (trace * trace - trace_sq);
    trace > 0.0 && pairs > COLLINEAR_TOLERANCE * trace * trace
}

/// One Jacobi rotation in the (p, q) plane: A ← Jᵀ A J, V ← V J, zeroing A_pq.
fn jacobi_rotate(a: &mut [[f64; 4]; 4], v: &mut [[f64; 4]; 4], p: usize, q: usize) {
    let apq = at(a, p, q);
    if apq == 0.0 {
        return;
    }
    // θ = (A_qq − A_pp) / (2 A_pq), t = sgn θ / (|θ| + √(θ² + 1)), c = 1/√(t² + 1), s = t c
    let theta = (at(a, q, q) - at(a, p, p)) / (2.0 * apq);
    let t = libm::copysign(1.0, theta) / (libm::fabs(theta) + libm::sqrt(theta * theta + 1.0));
    let c = 1.0 / libm::sqrt(t * t + 1.0);
    let s = t * c;
    for k in 0..4 {
        let (akp, akq) = (at(a, k, p), at(a, k, q));
        set(a, k, p, c * akp - s * akq);
        set(a, k, q, s * akp + c * akq);
    }
    for k in 0..4 {
        let (apk, aqk) = (at(a, p, k), at(a, q, k));
        set(a, p, k, c * apk - s * aqk);
        set(a, q, k, s * apk + c * aqk);
    }
    for k in 0..4 {
        let (vkp, vkq) = (at(v, k, p), at(v, k, q));
        set(v, k, p, c * vkp - s * vkq);
        set(v, k, q, s * vkp + c * vkq);
    }
}

/// The unit eigenvector of the largest eigenvalue of the symmetric `a` (cyclic Jacobi).
fn largest_eigenvector(mut a: [[f64; 4]; 4]) -> [f64; 4] {
    let mut v = [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]];
    let total: f64 = a.iter().flatten().map(|x| x * x).sum();
    for _ in 0..MAX_SWEEPS {
        let off: f64 = (0..4).flat_map(|p| (p + 1..4).map(move |q| (p, q))).map(|(p, q)| at(&a, p, q) * at(&a, p, q)).sum();
        if !(off > 1e-34 * total) {
            break;
        }
        for p in 0..3 {
            for q in p + 1..4 {
                jacobi_rotate(&mut a, &mut v, p, q);
            }
        }
    }
    let mut best = 0;
    for k in 1..4 {
        if at(&a, k, k) > at(&a, best, best) {
            best = k;
        }
    }
    [at(&v, 0, best), at(&v, 1, best), at(&v, 2, best), at(&v, 3, best)]
}

/// R of the unit quaternion (w, x, y, z) (normalised first), rows.
pub fn quaternion_rotation(q: [f64; 4]) -> [V3; 3] {
    let n = libm::sqrt(q.iter().map(|v| v * v).sum::<f64>());
    let [w, x, y, z] = q.map(|v| v / n);
    [
        [w * w + x * x - y * y - z * z, 2.0 * (x * y - w * z), 2.0 * (x * z + w * y)],
        [2.0 * (x * y + w * z), w * w - x * x + y * y - z * z, 2.0 * (y * z - w * x)],
        [2.0 * (x * z - w * y), 2.0 * (y * z + w * x), w * w - x * x - y * y + z * z],
    ]
}

/// R v, `r` by rows.
#[inline(always)]
pub fn rotate(r: &[V3; 3], v: V3) -> V3 {
    [dot(r[0], v), dot(r[1], v), dot(r[2], v)]
}

/// The least-squares rigid frame mapping `nominal` onto `measured` (same length): `None` for
/// different lengths, non-finite values, or nominal points that do not determine an orientation
/// ([`determines_orientation`]).
pub fn fit_frame(nominal: &[V3], measured: &[V3]) -> Option<FrameFit> {
    if nominal.len() != measured.len() || !determines_orientation(nominal) || measured.iter().flatten().any(|v| !v.is_finite()) {
        return None;
    }
    let (p_bar, y_bar) = (centroid(nominal), centroid(measured));
    // S = Σ p'_j y'_jᵀ
    let mut s = [[0.0; 3]; 3];
    for (p, y) in nominal.iter().zip(measured) {
        let (pc, yc) = (sub(*p, p_bar), sub(*y, y_bar));
        for (row, pa) in s.iter_mut().zip(pc) {
            for (sab, yb) in row.iter_mut().zip(yc) {
                *sab += pa * yb;
            }
        }
    }
    let [[sxx, sxy, sxz], [syx, syy, syz], [szx, szy, szz]] = s;
    // Horn (1987), eq. of N: the quaternion of the best rotation maximises qᵀ N q.
    let horn = [
        [sxx + syy + szz, syz - szy, szx - sxz, sxy - syx],
        [syz - szy, sxx - syy - szz, sxy + syx, szx + sxz],
        [szx - sxz, sxy + syx, -sxx + syy - szz, syz + szy],
        [sxy - syx, szx + sxz, syz + szy, -sxx - syy + szz],
    ];
    let rotation = quaternion_rotation(largest_eigenvector(horn));
    // t = ȳ − R p̄
    let origin = sub(y_bar, rotate(&rotation, p_bar));
    let mut sum = 0.0;
    for (p, y) in nominal.iter().zip(measured) {
        let e = sub(add_v(rotate(&rotation, *p), origin), *y);
        sum += dot(e, e);
    }
    let residual = libm::sqrt(sum / nominal.len() as f64);
    let finite = rotation.iter().flatten().chain(origin.iter()).all(|v| v.is_finite()) && residual.is_finite();
    finite.then_some(FrameFit { rotation, origin, residual })
}

#[inline(always)]
fn add_v(a: V3, b: V3) -> V3 {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

/// The fitted frame's velocity from the points' velocities: `velocities[j]` = dy_j. Returns
/// (dt, ω), the origin's linear velocity and the frame's angular velocity (dR = [ω]× R), from the
/// derivative of the fit's optimality condition Σ a_j × b_j = 0 (a_j = R p'_j, b_j = y'_j):
///
/// ```text
/// M ω = −Σ_j a_j × dy_j,   M = Σ_j a_j b_jᵀ − (Σ_j a_j · b_j) I,     dt = dȳ + (R p̄) × ω
/// ```
///
/// `None` when M is singular (the orientation undetermined) or the sizes differ.
pub fn frame_velocity(fit: &FrameFit, nominal: &[V3], measured: &[V3], velocities: &[V3]) -> Option<(V3, V3)> {
    let solver = FrameVelocity::new(fit, nominal, measured)?;
    solver.apply(velocities)
}

/// [`frame_velocity`] with M⁻¹ computed once, for several velocity columns (one per joint).
#[derive(Debug, Clone, Copy)]
pub struct FrameVelocity {
    m_inverse: [V3; 3],
    rotated: [V3; cbd_protocol::MAX_TOOL_POINTS],
    count: usize,
    lever: V3,
}

impl FrameVelocity {
    /// M⁻¹ and the rotated centred nominal points a_j of `fit`.
    pub fn new(fit: &FrameFit, nominal: &[V3], measured: &[V3]) -> Option<FrameVelocity> {
        let count = nominal.len();
        if count != measured.len() || count > cbd_protocol::MAX_TOOL_POINTS || count == 0 {
            return None;
        }
        let (p_bar, y_bar) = (centroid(nominal), centroid(measured));
        let mut rotated = [ZERO; cbd_protocol::MAX_TOOL_POINTS];
        let mut m = [[0.0; 3]; 3];
        let mut ab = 0.0;
        for ((a_j, p), y) in rotated.iter_mut().zip(nominal).zip(measured) {
            *a_j = rotate(&fit.rotation, sub(*p, p_bar));
            let b = sub(*y, y_bar);
            for (row, aa) in m.iter_mut().zip(*a_j) {
                for (mab, bb) in row.iter_mut().zip(b) {
                    *mab += aa * bb;
                }
            }
            ab += dot(*a_j, b);
        }
        for (k, row) in m.iter_mut().enumerate() {
            if let Some(d) = row.get_mut(k) {
                *d -= ab;
            }
        }
        let m_inverse = inverse3(&m)?;
        Some(FrameVelocity { m_inverse, rotated, count, lever: rotate(&fit.rotation, p_bar) })
    }

    /// (dt, ω) for the points' velocities `velocities` (one per tool point).
    pub fn apply(&self, velocities: &[V3]) -> Option<(V3, V3)> {
        if velocities.len() != self.count {
            return None;
        }
        let mut torque = ZERO;
        let mut mean = ZERO;
        for (a, dy) in self.rotated.iter().zip(velocities) {
            add_scaled(&mut torque, cross(*a, *dy), -1.0);
            add_scaled(&mut mean, *dy, 1.0 / self.count as f64);
        }
        let omega = rotate(&self.m_inverse, torque);
        Some((add_v(mean, cross(self.lever, omega)), omega))
    }
}

/// The inverse of a 3 × 3 matrix (adjugate over determinant); `None` when it is singular
/// relative to its size (|det| ≤ 1e-12 |M|³) or not finite.
fn inverse3(m: &[V3; 3]) -> Option<[V3; 3]> {
    let [r0, r1, r2] = *m;
    // Rows of the inverse are the columns of the adjugate: cross products of the rows.
    let (c0, c1, c2) = (cross(r1, r2), cross(r2, r0), cross(r0, r1));
    let det = dot(r0, c0);
    let size = m.iter().flatten().fold(0.0f64, |s, v| s.max(libm::fabs(*v)));
    if !(libm::fabs(det) > 1e-12 * size * size * size) {
        return None;
    }
    let inv = 1.0 / det;
    Some([[c0[0] * inv, c1[0] * inv, c2[0] * inv], [c0[1] * inv, c1[1] * inv, c2[1] * inv], [c0[2] * inv, c1[2] * inv, c2[2] * inv]])
}

/// The rotation vector θ·u of `r` (rows): R = exp([θ u]×), θ ∈ [0, π]. Near π the axis comes from
/// the largest diagonal entry of (R + I)/2, so the result stays accurate there.
pub fn rotation_vector(r: &[V3; 3]) -> V3 {
    let [[r00, r01, r02], [r10, r11, r12], [r20, r21, r22]] = *r;
    // 2 sin θ u = vee(R − Rᵀ), 2 cos θ + 1 = tr R
    let v = [r21 - r12, r02 - r20, r10 - r01];
    let sin2 = libm::sqrt(dot(v, v));
    let cos2 = r00 + r11 + r22 - 1.0;
    let theta = libm::atan2(sin2, cos2);
    if theta < 3.0 {
        // θ / (2 sin θ) v, with its limit 1/2 at θ = 0.
        let f = if sin2 > 1e-300 { theta / sin2 } else { 0.5 };
        return scale(v, f);
    }
    // Near π: (R + Rᵀ)/2 − cos θ I = (1 − cos θ) u uᵀ; its column k (the largest diagonal) ∝ u, sign from v.
    let c = 0.5 * cos2;
    let sym = [
        [r00 - c, 0.5 * (r01 + r10), 0.5 * (r02 + r20)],
        [0.5 * (r10 + r01), r11 - c, 0.5 * (r12 + r21)],
        [0.5 * (r20 + r02), 0.5 * (r21 + r12), r22 - c],
    ];
    let mut k = 0;
    for i in 1..3 {
        if at(&sym, i, i) > at(&sym, k, k) {
            k = i;
        }
    }
    let cols = sym;
    let mut u = cols.get(k).copied().unwrap_or(ZERO);
    let n = libm::sqrt(dot(u, u));
    if !(n > 0.0) {
        return ZERO;
    }
    u = scale(u, 1.0 / n);
    if dot(u, v) < 0.0 {
        u = scale(u, -1.0);
    }
    scale(u, theta)
}

/// R_a R_bᵀ (rows), the rotation from frame b to frame a.
pub fn relative_rotation(a: &[V3; 3], b: &[V3; 3]) -> [V3; 3] {
    [
        [dot(a[0], b[0]), dot(a[0], b[1]), dot(a[0], b[2])],
        [dot(a[1], b[0]), dot(a[1], b[1]), dot(a[1], b[2])],
        [dot(a[2], b[0]), dot(a[2], b[1]), dot(a[2], b[2])],
    ]
}

#[cfg(test)]
mod tests;

//! Spatial algebra: 3-vectors and rigid transforms (SE(3)), the one copy the runtime's kinematics,
//! its inverse kinematics and the trainer's model files share (as pinocchio's `SE3`).
//!
//! f64, no fused multiply-add, no panic path: the DH walk multiplies these frames, so every
//! operation here fixes the bits of k0.

use cbd_protocol::Transform;

/// A vector of R³ (a point or a direction), in the frame and unit of its context.
pub type V3 = [f64; 3];

/// The zero vector.
pub const ZERO: V3 = [0.0; 3];

/// a × b.
#[inline(always)]
pub fn cross(a: V3, b: V3) -> V3 {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}

/// a · b, summed in order.
#[inline(always)]
pub fn dot(a: V3, b: V3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// a − b.
#[inline(always)]
pub fn sub(a: V3, b: V3) -> V3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

/// a + b.
#[inline(always)]
pub fn add(a: V3, b: V3) -> V3 {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

/// s a.
#[inline(always)]
pub fn scale(a: V3, s: f64) -> V3 {
    [a[0] * s, a[1] * s, a[2] * s]
}

/// `acc += s·a`.
#[inline(always)]
pub fn add_scaled(acc: &mut V3, a: V3, s: f64) {
    for (o, v) in acc.iter_mut().zip(a) {
        *o += s * v;
    }
}

/// |a|, the Euclidean norm (correctly rounded square root).
#[inline(always)]
pub fn norm(a: V3) -> f64 {
    libm::sqrt(dot(a, a))
}

/// A rigid transform p ↦ R p + t (an element of SE(3)), stored as the 3×4 row-major matrix
/// [R | t]: `frame[i] = [R_i0, R_i1, R_i2, t_i]` (the frame dereferences to that matrix). Read as
/// a pose, R's columns are the frame's x, y and z axes and t its origin, in the parent frame;
/// t is in the chain's length unit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Frame(pub [[f64; 4]; 3]);

impl core::ops::Deref for Frame {
    type Target = [[f64; 4]; 3];
    fn deref(&self) -> &Self::Target {
        &self.0
    }
}

impl core::ops::DerefMut for Frame {
    fn deref_mut(&mut self) -> &mut Self::Target {
        &mut self.0
    }
}

impl Frame {
    /// R = I, t = 0.
    pub const IDENTITY: Frame = Frame([[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0]]);

    /// The frame of rotation `r` (`r[row][col]`) and translation `t`.
    pub const fn new(r: [[f64; 3]; 3], t: V3) -> Frame {
        let [[r00, r01, r02], [r10, r11, r12], [r20, r21, r22]] = r;
        Frame([[r00, r01, r02, t[0]], [r10, r11, r12, t[1]], [r20, r21, r22, t[2]]])
    }

    /// A blob's transform (row-major rotation, translation) as a frame.
    pub const fn from_transform(t: &Transform) -> Frame {
        let [r00, r01, r02, r10, r11, r12, r20, r21, r22] = t.rotation;
        Frame::new([[r00, r01, r02], [r10, r11, r12], [r20, r21, r22]], t.translation)
    }

    /// The frame as a blob's transform.
    pub const fn to_transform(&self) -> Transform {
        let [[r00, r01, r02, t0], [r10, r11, r12, t1], [r20, r21, r22, t2]] = self.0;
        Transform { rotation: [r00, r01, r02, r10, r11, r12, r20, r21, r22], translation: [t0, t1, t2] }
    }

    /// R, `r[row][col]`.
    pub const fn rotation(&self) -> [[f64; 3]; 3] {
        let [[r00, r01, r02, _], [r10, r11, r12, _], [r20, r21, r22, _]] = self.0;
        [[r00, r01, r02], [r10, r11, r12], [r20, r21, r22]]
    }

    /// t.
    pub const fn translation(&self) -> V3 {
        let [[_, _, _, t0], [_, _, _, t1], [_, _, _, t2]] = self.0;
        [t0, t1, t2]
    }

    /// The same rotation with translation `t`.
    pub const fn with_translation(self, t: V3) -> Frame {
        Frame::new(self.rotation(), t)
    }

    /// `self ∘ other` (first `other`, then `self`): [R_a R_b | R_a t_b + t_a], each entry summed
    /// as t_a + Σ_k a_ik b_kj with k in order (the DH walk's products).
    pub fn compose(&self, other: &Frame) -> Frame {
        let mut out = [[0.0; 4]; 3];
        for (out_i, a_i) in out.iter_mut().zip(self.0.iter()) {
            let [a_i0, a_i1, a_i2, a_i3] = *a_i;
            *out_i = [0.0, 0.0, 0.0, a_i3];
            for (a_ik, b_k) in [a_i0, a_i1, a_i2].into_iter().zip(other.0.iter()) {
                for (s, b_kj) in out_i.iter_mut().zip(b_k.iter()) {
                    *s += a_ik * b_kj;
                }
            }
        }
        Frame(out)
    }

    /// The inverse [Rᵀ | −Rᵀ t].
    pub fn inverse(&self) -> Frame {
        let r = self.rotation();
        let t = self.translation();
        let column = |c: usize| r.map(|row| row.get(c).copied().unwrap_or(0.0));
        let row = |c: usize| {
            let [x, y, z] = column(c);
            // −Σ_k R_kc t_k, summed over k in order.
            [x, y, z, -[x, y, z].iter().zip(t).map(|(r_kc, t_k)| r_kc * t_k).sum::<f64>()]
        };
        Frame([row(0), row(1), row(2)])
    }

    /// R v (a direction), each entry Σ_k R_ik v_k summed in order.
    pub fn rotate(&self, v: V3) -> V3 {
        self.rotation().map(|row| row.iter().zip(v).map(|(r_ik, v_k)| r_ik * v_k).sum())
    }

    /// R p + t (a point).
    pub fn apply(&self, p: V3) -> V3 {
        add(self.rotate(p), self.translation())
    }
}

//! The rigid chain's geometry at one configuration (joint axes, axis points, link ends and
//! rotations in the base frame), which the effects and the gravity torques differentiate (with the
//! vector algebra of [`crate::kinematics::spatial`]). One owner, so `augmented` and `gravity` both build on it.
//!
//! f64 through `libm`, no fused multiply-add, no panic path.

use crate::kinematics::rigid::dh_walk;
use crate::kinematics::spatial::{cross, sub, V3, ZERO};
use cbd_protocol::{GravityModel, JointKind, NominalModel, MAX_JOINTS as NJ};

#[inline(always)]
pub(crate) fn at<T: Copy + Default>(s: &[T], i: usize) -> T {
    s.get(i).copied().unwrap_or_default()
}

#[inline(always)]
pub(crate) fn at2<T: Copy + Default, const N: usize>(s: &[[T; N]], i: usize, j: usize) -> T {
    s.get(i).and_then(|r| r.get(j)).copied().unwrap_or_default()
}

/// The three indices in ascending order.
#[inline(always)]
pub(crate) fn sorted3(i: usize, j: usize, k: usize) -> (usize, usize, usize) {
    let (lo, hi) = (i.min(j), i.max(j));
    (lo.min(k), hi.min(k).max(lo), hi.max(k))
}

/// The rigid chain's geometry at one configuration, in the base frame.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Chain {
    pub n: usize,
    /// z_j: the unit axis of joint j.
    pub axes: [V3; NJ],
    /// o_j: a point on axis j.
    pub origins: [V3; NJ],
    pub prismatic: [bool; NJ],
    /// c_k: the distal end of link k, the origin of link k's own frame.
    pub ends: [V3; NJ],
    /// R_k: the rotation of link k's own frame (rows), planar: x along the link, z the joint axis.
    pub rotations: [[V3; 3]; NJ],
    /// The start of link 0 (base origin).
    pub start: V3,
}

impl Chain {
    /// Planar: links from the origin, joints about z. DH: c_k the origin of frame k+1 after the
    /// full joint transform (standard and modified conventions), start the base origin.
    pub(crate) fn of(model: &NominalModel, q: &[f64]) -> Chain {
        let mut out = Chain {
            n: 0,
            axes: [ZERO; NJ],
            origins: [ZERO; NJ],
            prismatic: [false; NJ],
            ends: [ZERO; NJ],
            rotations: [[ZERO; 3]; NJ],
            start: ZERO,
        };
        match model {
            NominalModel::PlanarChain { lengths, .. } => {
                let (mut p, mut theta) = (ZERO, 0.0);
                let slots = out.axes.iter_mut().zip(out.origins.iter_mut()).zip(out.ends.iter_mut().zip(out.rotations.iter_mut()));
                for ((l, qk), ((axis, origin), (end, rotation))) in lengths.iter().zip(q).zip(slots) {
                    *axis = [0.0, 0.0, 1.0];
                    *origin = p;
                    theta += qk;
                    let (s, c) = (libm::sin(theta), libm::cos(theta));
                    p[0] += l * c;
                    p[1] += l * s;
                    *end = p;
                    // R_k = Rz(q_1 + … + q_k)
                    *rotation = [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]];
                    out.n += 1;
                }
            }
            NominalModel::DhChain(chain) => {
                let walk = dh_walk(chain, q);
                out.start = walk.start;
                (out.axes, out.origins, out.ends, out.rotations) = (walk.axes, walk.origins, walk.ends, walk.end_rotations);
                for (prismatic, joint) in out.prismatic.iter_mut().zip(chain.joints.iter()).take(q.len()) {
                    *prismatic = joint.kind == JointKind::Prismatic;
                    out.n += 1;
                }
            }
        }
        out
    }

    /// ∂w/∂q_a of a vector w carried by the links after joint a: z_a × w, or 0 (prismatic).
    #[inline(always)]
    pub(crate) fn carry(&self, a: usize, w: &V3) -> V3 {
        if at(&self.prismatic, a) {
            ZERO
        } else {
            cross(at(&self.axes, a), *w)
        }
    }

    /// ∂c/∂q_a of a point c after joint a: z_a × (c − o_a), or z_a (prismatic).
    #[inline(always)]
    pub(crate) fn point_rate(&self, a: usize, c: &V3) -> V3 {
        let z = at(&self.axes, a);
        if at(&self.prismatic, a) {
            z
        } else {
            cross(z, sub(*c, at(&self.origins, a)))
        }
    }

    /// `g·carry(a, w) = gz_a·w`: gz_a = g × z_a (revolute) or 0 (prismatic).
    #[inline(always)]
    pub(crate) fn gravity_dual(&self, a: usize, g: &V3) -> V3 {
        if at(&self.prismatic, a) {
            ZERO
        } else {
            cross(*g, at(&self.axes, a))
        }
    }
}

/// The gravity vector the chain sees: planar chains use the first two entries.
pub(crate) fn gravity_vector(model: &NominalModel, gravity: &GravityModel) -> V3 {
    let [x, y, z] = gravity.direction;
    match model {
        NominalModel::PlanarChain { .. } => [x, y, 0.0],
        NominalModel::DhChain(_) => [x, y, z],
    }
}

/// How many derivatives to compute.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Order {
    /// The value alone.
    Value,
    /// The value and the first derivatives.
    First,
    /// The value, the first and the second derivatives.
    Second,
}

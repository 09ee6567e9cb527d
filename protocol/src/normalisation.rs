//! Task-space units: the one place the model's (the user's) units and the flow's internal units
//! meet (docs/DESIGN.md §1). Internal = (user − offset) / scale for positions; lengths (kernel
//! widths, σ, RMS errors, distances) only scale, variances scale squared.
//!
//! Each conversion is written once here so that its floating-point operations, and so every blob's
//! bytes, are the same wherever it is used: the division is a division (not a multiplication by
//! 1/scale), the offset is subtracted before it and added after the product. k0 and the task
//! flows' starts have always been normalised by the reciprocal, (y − o) · (1/s), which rounds
//! differently and which blobs record: the `_by_reciprocal` pair is that arithmetic, written once.

use serde::{Deserialize, Serialize};

use crate::limits::MAX_TASK_DIM;

/// Task-space normalisation: internal = (user − offset) / scale.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Normalisation {
    /// The offset (model units; the first `task_dim` entries are used).
    pub task_offset: [f64; MAX_TASK_DIM],
    /// The scale (model units per internal unit, > 0).
    pub task_scale: f64,
}

impl Normalisation {
    /// Internal units are the model's units.
    pub const IDENTITY: Normalisation = Normalisation { task_offset: [0.0; MAX_TASK_DIM], task_scale: 1.0 };

    /// The offset of task coordinate `axis` (0 past [`MAX_TASK_DIM`], where no model has one).
    #[inline]
    pub fn offset(&self, axis: usize) -> f64 {
        self.task_offset.get(axis).copied().unwrap_or(0.0)
    }

    /// Coordinate `axis` of a position, user → internal: (y − o_axis) / s.
    #[inline]
    pub fn position_to_internal(&self, axis: usize, user: f64) -> f64 {
        (user - self.offset(axis)) / self.task_scale
    }

    /// Coordinate `axis` of a position, internal → user: o_axis + s · k.
    #[inline]
    pub fn position_to_user(&self, axis: usize, internal: f64) -> f64 {
        self.offset(axis) + self.task_scale * internal
    }

    /// Coordinate `axis` of a position, user → internal by the reciprocal: (y − o_axis) · (1/s).
    /// Not [`Self::position_to_internal`]'s bits: k0's normalisation (`Kinematics::normalised`,
    /// trainer and runtime) and the runtime's task flows multiply, and blobs record the product.
    #[inline]
    pub fn position_to_internal_by_reciprocal(&self, axis: usize, user: f64) -> f64 {
        (user - self.offset(axis)) * (1.0 / self.task_scale)
    }

    /// A length (a derivative of a position), user → internal by the reciprocal: l · (1/s), as
    /// [`Self::position_to_internal_by_reciprocal`] (k0's Jacobian and Hessian).
    #[inline]
    pub fn length_to_internal_by_reciprocal(&self, user: f64) -> f64 {
        user * (1.0 / self.task_scale)
    }

    /// A length (a kernel width, σ, a displacement, an RMS error), user → internal: l / s.
    #[inline]
    pub fn length_to_internal(&self, user: f64) -> f64 {
        user / self.task_scale
    }

    /// A length, internal → user: s · l.
    #[inline]
    pub fn length_to_user(&self, internal: f64) -> f64 {
        self.task_scale * internal
    }

    /// A variance (length squared, e.g. γ_W), user → internal: v / s².
    #[inline]
    pub fn variance_to_internal(&self, user: f64) -> f64 {
        user / (self.task_scale * self.task_scale)
    }

    /// A variance, internal → user: (v · s) · s (this order: the evidence's choices have always
    /// been converted so, and a blob records them).
    #[inline]
    pub fn variance_to_user(&self, internal: f64) -> f64 {
        internal * self.task_scale * self.task_scale
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn conversions_invert_each_other_and_keep_their_operation_order() {
        let norm = Normalisation { task_offset: [0.1, -0.2, 0.3], task_scale: 0.7 };
        for (axis, y) in [(0, 1.234), (1, -5.5), (2, 1e-3)] {
            let k = norm.position_to_internal(axis, y);
            assert_eq!(k.to_bits(), ((y - norm.task_offset[axis]) / 0.7).to_bits());
            assert!((norm.position_to_user(axis, k) - y).abs() <= 1e-15 * (1.0 + y.abs()));
        }
        assert_eq!(norm.position_to_user(5, 2.0), 1.4, "no offset past the task dimension");
        assert_eq!(norm.length_to_user(2.0).to_bits(), (2.0f64 * 0.7).to_bits());
        assert_eq!(norm.length_to_internal(2.0).to_bits(), (2.0f64 / 0.7).to_bits());
        assert_eq!(norm.variance_to_internal(2.0).to_bits(), (2.0f64 / (0.7 * 0.7)).to_bits());
        assert_eq!(norm.variance_to_user(2.0).to_bits(), (2.0f64 * 0.7 * 0.7).to_bits());
        assert!((norm.variance_to_user(norm.variance_to_internal(3.0)) - 3.0).abs() < 1e-15);
        let inv = 1.0f64 / 0.7;
        assert_eq!(norm.position_to_internal_by_reciprocal(1, 2.0).to_bits(), ((2.0f64 - -0.2) * inv).to_bits());
        assert_eq!(norm.length_to_internal_by_reciprocal(2.0).to_bits(), (2.0f64 * inv).to_bits());
        assert_ne!((0.3f64 * inv).to_bits(), (0.3f64 / 0.7).to_bits(), "the reciprocal rounds differently");
    }
}

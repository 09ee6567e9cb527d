//! The nominal forward kinematics k0 and its derivatives, in the model's own units: the rigid DH
//! chain beside its derivatives (`rigid`, `rigid_derivatives`), the physical effects on top of it
//! beside theirs (`augmented`, `augmented_derivatives`, with the gravity torques of a mass model in
//! `gravity`), and the dispatch between them here.

pub mod augmented;
pub mod augmented_derivatives;
mod chain;
pub mod gravity;
pub mod rigid;
pub mod rigid_derivatives;
pub mod spatial;
pub mod tool_frame;
pub mod tool_point;

use cbd_protocol::NominalModel;

pub use rigid::{dh_frames, Kinematics};
pub use spatial::Frame;
pub use tool_point::{forward_kinematics_at, with_tool_point};

/// k0(x) and Dk0(x). `x` has one entry per joint (radians, or length units for prismatic joints).
/// A model with effects gives the augmented k0_aug and Dk0_aug ([`crate::kinematics::augmented::kinematics`]).
pub fn forward_kinematics(model: &NominalModel, x: &[f64]) -> Kinematics {
    // Effect-free models take the rigid chain's code below, unchanged (same bits, same cost).
    if !model.effects().is_empty() {
        return crate::kinematics::augmented::kinematics(model, x);
    }
    crate::kinematics::rigid::kinematics(model, x)
}

#[cfg(test)]
mod tests {
    use super::*;
    use cbd_protocol::{DhChain, DhConvention, DhJoint, Effects, JointKind, Transform, MAX_JOINTS};
    use heapless::Vec as HVec;

    fn check_jacobian(model: &NominalModel, x: &[f64]) {
        let k = forward_kinematics(model, x);
        let h = 1e-6;
        for d in 0..x.len() {
            let mut xa = [0.0; MAX_JOINTS];
            let mut xb = [0.0; MAX_JOINTS];
            xa[..x.len()].copy_from_slice(x);
            xb[..x.len()].copy_from_slice(x);
            xa[d] += h;
            xb[d] -= h;
            let (ka, kb) = (forward_kinematics(model, &xa[..x.len()]), forward_kinematics(model, &xb[..x.len()]));
            for c in 0..model.task_dim() {
                let fd = (ka.position[c] - kb.position[c]) / (2.0 * h);
                let scale = 1.0 + fd.abs();
                assert!((fd - k.jacobian[c][d]).abs() < 1e-6 * scale, "row {c} joint {d}: fd {fd} vs {}", k.jacobian[c][d]);
            }
        }
    }

    #[test]
    fn planar_rr_matches_closed_form_and_finite_differences() {
        let model = NominalModel::planar(&[1.0, 0.5]).unwrap();
        let x = [0.7, -1.9];
        let k = forward_kinematics(&model, &x);
        let y = [libm::cos(0.7) + 0.5 * libm::cos(0.7 - 1.9), libm::sin(0.7) + 0.5 * libm::sin(0.7 - 1.9)];
        assert!((k.position[0] - y[0]).abs() < 1e-15 && (k.position[1] - y[1]).abs() < 1e-15);
        check_jacobian(&model, &x);
    }

    fn six_joint(convention: DhConvention) -> NominalModel {
        let j = |kind, a, alpha: f64, d| DhJoint { kind, a, alpha, d, theta_offset: 0.1 };
        let mut tool = Transform::IDENTITY;
        tool.translation = [0.01, 0.02, 0.031];
        NominalModel::DhChain(DhChain {
            convention,
            joints: HVec::from_slice(&[
                j(JointKind::Revolute, 0.0, core::f64::consts::FRAC_PI_2, 0.089),
                j(JointKind::Revolute, -0.425, 0.0, 0.0),
                j(JointKind::Prismatic, -0.392, 0.2, 0.0),
                j(JointKind::Revolute, 0.0, core::f64::consts::FRAC_PI_2, 0.109),
                j(JointKind::Revolute, 0.0, -core::f64::consts::FRAC_PI_2, 0.094),
                j(JointKind::Revolute, 0.0, 0.0, 0.082),
            ])
            .unwrap(),
            base: Transform { rotation: [0.0, -1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0], translation: [0.1, 0.0, 0.2] },
            tool,
            effects: Effects::NONE,
            tool_points: HVec::new(),
        })
    }

    #[test]
    fn dh_chains_jacobian_matches_finite_differences() {
        for conv in [DhConvention::Standard, DhConvention::Modified] {
            check_jacobian(&six_joint(conv), &[0.3, -0.8, 0.05, 1.2, -0.4, 2.0]);
        }
    }
}

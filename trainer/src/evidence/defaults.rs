//! The default every model selection starts from: one unit kernel axis per joint (the task-space
//! normalisation, the other default, is the data's own: [`crate::data::Measurements::normalisation`]).

use cbd_protocol::{JointKernel, NominalModel};

/// One axis per joint: periodic (b = 1) for revolute joints, Gaussian (width 1) for prismatic ones.
pub fn default_joint_kernel(nominal: &NominalModel) -> JointKernel {
    let axes = crate::axis_forms::default_axes(nominal).into_iter().take(cbd_protocol::MAX_JOINTS).collect();
    JointKernel { gamma: 1.0, axes }
}

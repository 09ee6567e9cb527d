//! The defaults every model selection starts from: the task-space normalisation of the data
//! (docs/DESIGN.md §1) and one unit kernel axis per joint.

use crate::data::Measurements;
use cbd_protocol::{JointKernel, NominalModel, Normalisation};

/// Task-space normalisation from data: offset = mean position, scale = RMS distance to it
/// ([`Measurements::normalisation`]).
pub fn normalisation_of(data: &Measurements) -> Normalisation {
    data.normalisation()
}

/// One axis per joint: periodic (b = 1) for revolute joints, Gaussian (width 1) for prismatic ones.
pub fn default_joint_kernel(nominal: &NominalModel) -> JointKernel {
    let axes = crate::axis_forms::default_axes(nominal).into_iter().take(cbd_protocol::MAX_JOINTS).collect();
    JointKernel { gamma: 1.0, axes }
}

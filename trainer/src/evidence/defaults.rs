//! The defaults every model selection starts from: the task-space normalisation of the data
//! (docs/DESIGN.md §1) and one unit kernel axis per joint.

use crate::data::Measurements;
use cbd_protocol::{JointKernel, NominalModel, Normalisation};

/// Task-space normalisation from data: offset = mean position, scale = RMS distance to it.
pub fn normalisation_of(data: &Measurements) -> Normalisation {
    let m = data.task_dim;
    let count = data.len().max(1) as f64;
    let mut offset = [0.0; 3];
    for y in data.positions.chunks_exact(m) {
        for c in 0..m {
            offset[c] += y[c] / count;
        }
    }
    let r2: f64 = data.positions.chunks_exact(m).map(|y| (0..m).map(|c| (y[c] - offset[c]).powi(2)).sum::<f64>()).sum::<f64>() / count;
    let scale = if r2 > 0.0 && r2.is_finite() { r2.sqrt() } else { 1.0 };
    Normalisation { task_offset: offset, task_scale: scale }
}

/// One axis per joint: periodic (b = 1) for revolute joints, Gaussian (width 1) for prismatic ones.
pub fn default_joint_kernel(nominal: &NominalModel) -> JointKernel {
    let axes = crate::axis_forms::default_axes(nominal).into_iter().take(cbd_protocol::MAX_JOINTS).collect();
    JointKernel { gamma: 1.0, axes }
}

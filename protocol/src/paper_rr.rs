//! The paper's planar RR benchmark (docs/DESIGN.md §6): its link lengths and the kernels it
//! reports, written once for the demo's reproduction, the reference flow and the test blobs.

use crate::model::{JointKernel, JointKernelAxis, TaskKernel};

/// Nominal link lengths l1, l2.
pub const LENGTHS: [f64; 2] = [1.0, 0.5];
/// Joint-space field variance γ_V.
pub const JOINT_GAMMA: f64 = 8.0;
/// Periodic joint kernel exp(b (cos Δ − 1)), the same b on both joints.
pub const JOINT_B: f64 = 1.0186;
/// Task-space kernel width a.
pub const TASK_WIDTH: f64 = 1.027;

/// K_V of the paper: γ_V = 8, periodic with b = 1.0186 on both joints.
pub fn joint_kernel() -> JointKernel {
    let mut axes = heapless::Vec::new();
    for _ in 0..2 {
        // Two axes always fit: MAX_JOINTS ≥ 2.
        let _ = axes.push(JointKernelAxis::Periodic { b: JOINT_B });
    }
    JointKernel { gamma: JOINT_GAMMA, axes }
}

/// K_W of the paper: width a = 1.027.
pub fn task_kernel() -> TaskKernel {
    TaskKernel { width: TASK_WIDTH }
}

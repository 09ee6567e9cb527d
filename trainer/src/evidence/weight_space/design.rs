//! The periodic joint functions at every row: Φ_if = φ_f(q_i), products over the axes of cos h q_d or
//! sin h q_d (docs/DESIGN.md §11), through the runtime's own joint basis. They do not depend on the
//! kernels' b_d (those only set the prior variances), so a weight-space table forms them once.

use crate::data::Measurements;
use cbd_protocol::{JointKernel, JointKernelAxis};
use cbd_runtime::internals::expansion::{joint_row_len, write_joint_basis};
use faer::Mat;

/// Φ (N × r) for the basis `codes` (r functions × n axes, every axis periodic).
pub(crate) fn periodic_design(codes: &[u8], data: &Measurements) -> Mat<f64> {
    let n = data.n_joints;
    let (r, row_len) = (codes.len() / n.max(1), joint_row_len(n));
    // The runtime's periodic features do not depend on b: any b serves.
    let kernel = JointKernel { gamma: 1.0, axes: heapless::Vec::from_iter((0..n).map(|_| JointKernelAxis::Periodic { b: 1.0 })) };
    let mut basis = vec![0.0; r * row_len];
    let mut design = Mat::zeros(data.len(), r);
    for i in 0..data.len() {
        write_joint_basis(&kernel, codes, n, data.joints(i), &mut basis, false);
        for f in 0..r {
            design[(i, f)] = basis[f * row_len];
        }
    }
    design
}

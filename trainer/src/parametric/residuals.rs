//! The residuals r_i = k(p; x_i) − y_i of a DH chain over measured rows.

use crate::data::Measurements;
use cbd_protocol::{DhChain, NominalModel};
use cbd_runtime::kinematics::forward_kinematics;

/// k − y over the data's `m = data.task_dim` coordinates (2 for a planar arm's DH form).
pub(super) fn residuals(chain: &DhChain, data: &Measurements, out: &mut [f64]) {
    let model = NominalModel::DhChain(chain.clone());
    let m = data.task_dim;
    for i in 0..data.len() {
        let k = forward_kinematics(&model, data.joints(i));
        for c in 0..m {
            out[m * i + c] = k.position[c] - data.position(i)[c];
        }
    }
}

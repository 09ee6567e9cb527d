//! The residuals r_i = k(p; x_i) − y_i of a DH chain over measured rows.

use crate::data::Measurements;
use cbd_protocol::{DhChain, NominalModel};

/// k − y over the data's `m = data.task_dim` coordinates (2 for a planar arm's DH form).
pub(super) fn residuals(chain: &DhChain, data: &Measurements, out: &mut [f64]) {
    let k = crate::nominal::positions(&NominalModel::DhChain(chain.clone()), &data.joints, data.task_dim);
    for ((r, k), y) in out.iter_mut().zip(&k).zip(&data.positions) {
        *r = k - y;
    }
}

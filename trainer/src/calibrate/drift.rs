//! The pipeline's drift stage, when asked (`Settings::drift`; `cbd fit` asks): drift in measurement
//! order (issue 49 item 2) on the residual of the DH-calibrated chain — the chain CbD deforms, or
//! where the nominal was kept the chain the geometry choice fitted (a nominal chain's error of
//! millimetres leaves second-order shape the test's joint kernel must carry, and the UR5 rows'
//! drift went unseen there). The chain is fitted here only where no stage fitted it already.

use super::drift_test::{drift_of_chain, Drift, DriftOptions};
use crate::data::{Measurements, RowOrder};
use crate::parametric::DhCalibrationOptions;
use cbd_protocol::NominalModel;

/// The drift test of `data` for `nominal`, on `fitted`, the DH-calibrated chain the geometry choice
/// fitted (the chain CbD deforms when it chose it); without one, the chain fitted here, or
/// `nominal` as it stands where the DH fit cannot calibrate it.
pub fn drift_stage(nominal: &NominalModel, data: &Measurements, fitted: Option<NominalModel>, options: &DriftOptions) -> Option<Drift> {
    // Rows without a time of measurement are not tested: no chain to fit for them.
    if data.order == RowOrder::Unordered {
        return None;
    }
    let chain = fitted.unwrap_or_else(|| {
        crate::parametric::calibrate_dh(nominal, data, &DhCalibrationOptions::default()).map_or(nominal.clone(), |f| f.model)
    });
    drift_of_chain(&chain, data, options)
}

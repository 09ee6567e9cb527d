//! The pipeline's drift stage, when asked (`Settings::drift`; `cbd fit` asks): drift in measurement
//! order (issue 49 item 2) on the residual of the DH-calibrated chain — the chain CbD deforms, or
//! where the nominal was kept the chain the geometry choice fitted (a nominal chain's error of
//! millimetres leaves second-order shape the test's joint kernel must carry, and the UR5 rows'
//! drift went unseen there). The geometry stage fits that chain (once, where it fitted none for its
//! own choice); the rows tested were cut with the others (`data::stage_rows`).

use super::drift_test::{drift_of_chain, Drift, DriftOptions};
use crate::data::stage_rows::StageRows;
use cbd_protocol::NominalModel;

/// The drift test of `data`'s window on `chain`, the DH-calibrated chain the geometry stage fitted
/// (`nominal` as it stands where the DH fit cannot calibrate it). `None` where the rows have no
/// window (no time of measurement: rows declared unordered) or no chain was fitted.
pub fn drift_stage(data: &StageRows, chain: Option<NominalModel>, options: &DriftOptions) -> Option<Drift> {
    drift_of_chain(&chain?, data.drift.as_ref()?, options)
}

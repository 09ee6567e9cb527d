//! A peer as the harnesses see it ([`compare`](super::compare), [`commanded`](super::commanded),
//! [`commanded_pose`](super::commanded_pose)): its row name, whether it is also fitted on the
//! DH-calibrated chain (`dh+<name>`), how its correction is fitted, and how the commanded tables
//! turn a target into a joint command with it. The list itself is the CLI's (`face::peers`); no
//! harness names a peer.

use super::correction::{fit_on, fit_per_tool_point, CorrectionFitter, FittedCorrection};
use crate::data::Measurements;
use cbd_protocol::NominalModel;

/// Fits a calibrated model blob on a base model (CbD: the blob `cbd fit` writes for it).
pub type BlobFitter<'a> = &'a dyn Fn(&NominalModel, &Measurements) -> crate::Result<Vec<u8>>;

/// How the commanded tables command a peer's fit.
#[derive(Clone, Copy)]
pub enum Command<'a> {
    /// Pose redefinition through its corrected positions (kernel ridge): the inverse kinematics of
    /// the model it corrects, the target shifted by the correction's miss, five rounds. Its `dh+`
    /// row corrects the DH-calibrated chain (a planar arm: its DH form, commanded in closed form).
    PoseRedefinition,
    /// The blob's own compensation (`Calibrator::compensate`, `compensate_pose`), the blob fitted
    /// by this. Its `dh+` row's blob deforms the DH-calibrated chain (six-joint arms only).
    Compensate(BlobFitter<'a>),
}

/// One peer of CbD: the rows `name` (on the nominal model) and, with `on_dh`, `dh+name`.
#[derive(Clone, Copy)]
pub struct Peer<'a> {
    pub name: &'a str,
    /// Also fitted on the DH-calibrated chain, as the row `dh+<name>`.
    pub on_dh: bool,
    /// Fitted once per tool point ([`fit_per_tool_point`]: a function of the joints alone), else
    /// on the whole chain ([`fit_on`] for a planar arm's DH form).
    pub per_tool_point: bool,
    /// Its rows' chosen hyperparameters go under the JSON's `"hyperparameters"` (null when absent).
    pub hyperparameters_in_json: bool,
    pub fit: CorrectionFitter<'a>,
    /// How the commanded tables command it; `None`: no commanded rows.
    pub command: Option<Command<'a>>,
}

impl Peer<'_> {
    /// The row fitted on the DH-calibrated chain.
    pub fn dh_name(&self) -> String {
        format!("dh+{}", self.name)
    }

    /// Its correction of the nominal model.
    pub fn fit_on_nominal(&self, nominal: &NominalModel, data: &Measurements) -> crate::Result<FittedCorrection> {
        match self.per_tool_point {
            true => fit_per_tool_point(self.fit, nominal, data),
            false => (self.fit)(nominal, data),
        }
    }

    /// Its correction of a calibrated chain (for a planar arm, possibly its DH form).
    pub fn fit_on_chain(&self, chain: &NominalModel, data: &Measurements) -> crate::Result<FittedCorrection> {
        match self.per_tool_point {
            true => fit_per_tool_point(self.fit, chain, data),
            false => fit_on(self.fit, chain, data),
        }
    }
}

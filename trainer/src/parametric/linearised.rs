//! The geometric group linearised at a DH fit: the identification Jacobian at the fitted
//! parameters, the columns the data identify, and the fitted change they carry — what CbD's
//! evidence marginalises as explicit basis functions (docs/DESIGN.md §3, "the geometry choice").

use super::identifiable::{independent_columns, out_of_plane_parameters};
use super::jacobian::{column_scales, jacobian_at, zero_columns};
use super::{DhCalibrationOptions, DhFitStats};
use crate::data::Measurements;
use crate::nominal::dh_parameters::parameter_names_for;
use cbd_protocol::NominalModel;
use faer::Mat;

/// The geometric group around a DH fit p̂: k(p) ≈ k(p̂) + J (p − p̂) on the data's rows.
#[derive(Debug, Clone)]
pub struct LinearisedGroup {
    /// ∂k/∂p at p̂ (data units per parameter unit), `task_dim` rows per data row, one column per
    /// identifiable parameter.
    pub jacobian: Mat<f64>,
    /// The kept parameters' names (`nominal::dh_parameters`).
    pub names: Vec<String>,
    /// J p̂ over every parameter (data units, `task_dim` per row): added to the residual of the
    /// fitted chain it gives the nominal's residual to first order about p̂.
    pub shift: Vec<f64>,
}

/// The group of `nominal` (a DH chain or a planar arm's DH form) at the fitted changes
/// `fit.parameter_changes`, on `data`'s rows; `None` for a model without a DH form.
pub fn linearised_group(nominal: &NominalModel, fit: &DhFitStats, data: &Measurements) -> Option<LinearisedGroup> {
    let dh_form = crate::nominal::planar::as_dh(nominal);
    let NominalModel::DhChain(chain0) = &dh_form else { return None };
    let (n, m) = (chain0.joints.len(), data.task_dim);
    let p = &fit.parameter_changes;
    let np = p.len();
    let rows = m * data.len();
    let mut full = Mat::<f64>::zeros(rows, np);
    let (mut rp, mut rm) = (vec![0.0; rows], vec![0.0; rows]);
    jacobian_at(chain0, p, data, &mut full, (&mut rp, &mut rm));
    let out_of_plane = out_of_plane_parameters(n, m);
    zero_columns(&mut full, &out_of_plane);
    let mut colnorm = vec![0.0; np];
    column_scales(&full, &mut colnorm);
    let candidates: Vec<usize> = (0..np).filter(|k| !out_of_plane.contains(k)).collect();
    let kept = independent_columns(full.as_ref(), &colnorm, &candidates, DhCalibrationOptions::default().redundancy_tolerance);
    let shift = (0..rows).map(|i| (0..np).map(|k| full[(i, k)] * p[k]).sum()).collect();
    let names = parameter_names_for(chain0);
    Some(LinearisedGroup {
        jacobian: Mat::from_fn(rows, kept.len(), |i, j| full[(i, kept[j])]),
        names: kept.iter().map(|&k| names[k].clone()).collect(),
        shift,
    })
}

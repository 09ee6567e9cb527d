//! The identifiable parameters: those whose unit-scaled Jacobian column is not (numerically) in the
//! span of the others kept, chosen greedily by column-pivoted Gram–Schmidt.

use super::jacobian::{jacobian_at, zero_columns};
use super::least_squares::column_scales;
use super::DhCalibrationOptions;
use crate::data::Measurements;
use crate::nominal::dh_parameters::parameter_count;
use cbd_protocol::NominalModel;
use faer::Mat;

/// Column-pivoted Gram–Schmidt on the unit-scaled Jacobian: repeatedly keep the column with the
/// largest component orthogonal to those kept; columns left with less than `tol` are redundant.
pub(super) fn redundant_parameters(jac: &Mat<f64>, colnorm: &[f64], tol: f64) -> Vec<usize> {
    let (rows, np) = (jac.nrows(), jac.ncols());
    let mut cols: Vec<Vec<f64>> = (0..np).map(|k| (0..rows).map(|i| jac[(i, k)] / colnorm[k]).collect()).collect();
    let mut remaining: Vec<usize> = (0..np).collect();
    loop {
        let norms: Vec<f64> = remaining.iter().map(|&k| cols[k].iter().map(|v| v * v).sum::<f64>().sqrt()).collect();
        let Some((pos, &best)) = norms.iter().enumerate().max_by(|a, b| a.1.total_cmp(b.1)) else { break };
        if best <= tol {
            break;
        }
        let pivot = remaining.remove(pos);
        let q: Vec<f64> = cols[pivot].iter().map(|v| v / best).collect();
        for &k in &remaining {
            let d: f64 = q.iter().zip(&cols[k]).map(|(a, b)| a * b).sum();
            for (c, qi) in cols[k].iter_mut().zip(&q) {
                *c -= d * qi;
            }
        }
    }
    remaining.sort_unstable();
    remaining
}

/// The parameters a planar arm's data (m < 3 coordinates) cannot see, which never change
/// (first-order blind in the plane's coordinates); none for 3-D data.
pub(super) fn out_of_plane_parameters(n: usize, m: usize) -> Vec<usize> {
    if m >= 3 {
        return Vec::new();
    }
    let inside = crate::nominal::planar::in_plane_parameters(n);
    (0..parameter_count(n)).filter(|k| !inside.contains(k)).collect()
}

/// The parameters redundant at this Jacobian (none when `tolerance` is 0), less those out of the plane.
pub(super) fn redundant_in_plane(jac: &Mat<f64>, colnorm: &[f64], tolerance: f64, out_of_plane: &[usize]) -> Vec<usize> {
    if !(tolerance > 0.0) {
        return Vec::new();
    }
    let mut f = redundant_parameters(jac, colnorm, tolerance);
    f.retain(|k| !out_of_plane.contains(k));
    f
}

/// The geometric group's identification Jacobian at the nominal parameters, ∂k/∂p (the DH fit's own
/// Jacobian: `task_dim` rows per configuration of `joints`, row-major, `n` per row), and the
/// parameters it can identify: those that move the task coordinates (not out of the plane) and are
/// not redundant on these configurations (the fit's column-pivoted test and tolerance). `None` for a
/// model without a DH form.
pub fn identification_jacobian(nominal: &NominalModel, joints: &[f64]) -> Option<(Mat<f64>, Vec<usize>)> {
    let dh_form = crate::nominal::planar::as_dh(nominal);
    let NominalModel::DhChain(chain0) = &dh_form else { return None };
    let (n, m) = (chain0.joints.len(), nominal.task_dim());
    let count = joints.len() / n.max(1);
    let data = Measurements { n_joints: n, task_dim: m, joints: joints[..count * n].to_vec(), positions: vec![0.0; count * m] };
    let np = parameter_count(n);
    let mut jac = Mat::zeros(m * count, np);
    let (mut rp, mut rm) = (vec![0.0; m * count], vec![0.0; m * count]);
    jacobian_at(chain0, &vec![0.0; np], &data, &mut jac, (&mut rp, &mut rm));
    let out_of_plane = out_of_plane_parameters(n, m);
    zero_columns(&mut jac, &out_of_plane);
    let mut colnorm = vec![0.0; np];
    column_scales(&jac, &mut colnorm);
    let mut dropped = redundant_parameters(&jac, &colnorm, DhCalibrationOptions::default().redundancy_tolerance);
    dropped.extend(out_of_plane);
    let identifiable = (0..np).filter(|k| !dropped.contains(k)).collect();
    Some((jac, identifiable))
}

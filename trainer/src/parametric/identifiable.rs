//! The identifiable parameters: those whose unit-scaled Jacobian column is not (numerically) in the
//! span of the others kept, chosen by column-pivoted QR.

use super::jacobian::{column_scales, geometric_jacobian, zero_columns};
use super::DhCalibrationOptions;
use crate::nominal::dh_parameters::{parameter_count, parameter_count_for};
use cbd_protocol::NominalModel;
use faer::{Mat, MatRef};

/// The columns of `jac` among `candidates` that column-pivoted QR keeps, A D⁻¹ P = Q R (faer's
/// `col_piv_qr`, D = diag(`scales`), indexed by column of `jac`): pivot k is the column with the
/// largest part orthogonal to the k before it, and the columns kept are those pivoted while
/// |R_kk| > `tolerance`. For unit-scaled columns (`scales` their norms) the tolerance is relative
/// to each column's own norm: a column kept sticks out of the span of those kept before it by
/// more than `tolerance` of its length. Among exactly dependent columns (equal residual norms) the
/// later candidate is kept, as the column-pivoted Gram–Schmidt loops this replaced did: the columns
/// are offered to the QR in reverse order, and it pivots on the first largest. Sorted; empty for
/// no candidates or no rows.
pub fn independent_columns(jac: MatRef<'_, f64>, scales: &[f64], candidates: &[usize], tolerance: f64) -> Vec<usize> {
    if candidates.is_empty() || jac.nrows() == 0 {
        return Vec::new();
    }
    let last = candidates.len() - 1;
    let scaled = Mat::from_fn(jac.nrows(), candidates.len(), |i, j| jac[(i, candidates[last - j])] / scales[candidates[last - j]]);
    let qr = scaled.col_piv_qr();
    let r = qr.R();
    let (pivots, _) = qr.P().arrays();
    let mut kept: Vec<usize> =
        (0..r.nrows().min(r.ncols())).take_while(|&k| r[(k, k)].abs() > tolerance).map(|k| candidates[last - pivots[k]]).collect();
    kept.sort_unstable();
    kept
}

/// The parameters whose `colnorm`-scaled Jacobian column is redundant: those
/// [`independent_columns`] does not keep.
pub(super) fn redundant_parameters(jac: &Mat<f64>, colnorm: &[f64], tol: f64) -> Vec<usize> {
    let all: Vec<usize> = (0..jac.ncols()).collect();
    let kept = independent_columns(jac.as_ref(), colnorm, &all, tol);
    all.into_iter().filter(|k| !kept.contains(k)).collect()
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
    let np = parameter_count_for(chain0);
    let mut jac = geometric_jacobian(chain0, joints, m);
    let out_of_plane = out_of_plane_parameters(n, m);
    zero_columns(&mut jac, &out_of_plane);
    let mut colnorm = vec![0.0; np];
    column_scales(&jac, &mut colnorm);
    let mut dropped = redundant_parameters(&jac, &colnorm, DhCalibrationOptions::default().redundancy_tolerance);
    dropped.extend(out_of_plane);
    let identifiable = (0..np).filter(|k| !dropped.contains(k)).collect();
    Some((jac, identifiable))
}

#[cfg(test)]
mod tests {
    use super::super::tests::{sample, ur5_like};
    use super::*;
    use cbd_protocol::DhConvention;

    /// The greedy column-pivoted Gram–Schmidt the QR replaced (DH calibration's and diagnose's own
    /// copies), kept as the reference: repeatedly keep the column with the largest component
    /// orthogonal to those kept, until that component is at most `tol`.
    pub(crate) fn gram_schmidt_reference(jac: MatRef<'_, f64>, scales: &[f64], candidates: &[usize], tol: f64) -> Vec<usize> {
        let rows = jac.nrows();
        let mut cols: Vec<(usize, Vec<f64>)> =
            candidates.iter().map(|&k| (k, (0..rows).map(|i| jac[(i, k)] / scales[k]).collect())).collect();
        let mut kept = Vec::new();
        loop {
            let best = cols
                .iter()
                .enumerate()
                .map(|(pos, (_, v))| (pos, v.iter().map(|x| x * x).sum::<f64>().sqrt()))
                .max_by(|a, b| a.1.total_cmp(&b.1));
            let Some((pos, size)) = best else { break };
            if size <= tol {
                break;
            }
            let (k, v) = cols.remove(pos);
            let unit: Vec<f64> = v.iter().map(|x| x / size).collect();
            for (_, w) in cols.iter_mut() {
                let d: f64 = unit.iter().zip(w.iter()).map(|(a, b)| a * b).sum();
                for (x, u) in w.iter_mut().zip(&unit) {
                    *x -= d * u;
                }
            }
            kept.push(k);
        }
        kept.sort_unstable();
        kept
    }

    /// The QR's columns and the Gram–Schmidt reference's: as many, spanning the same space (neither
    /// set gains a column from the other), and the same set when no two columns tie. Where they
    /// differ the two picked different members of an exactly dependent group (e.g. a UR5's
    /// d2, d3, d4 along parallel axes, or a6 and the tool's x translation: equal columns), whose
    /// residual norms tie to rounding. The QR's columns.
    fn same_rank_and_span(jac: MatRef<'_, f64>, scales: &[f64], candidates: &[usize], tol: f64) -> Vec<usize> {
        let qr = independent_columns(jac, scales, candidates, tol);
        let gs = gram_schmidt_reference(jac, scales, candidates, tol);
        assert_eq!(qr.len(), gs.len(), "rank: QR {qr:?}, Gram–Schmidt {gs:?}");
        let union: Vec<usize> = candidates.iter().copied().filter(|k| qr.contains(k) || gs.contains(k)).collect();
        assert_eq!(independent_columns(jac, scales, &union, tol).len(), qr.len(), "span: QR {qr:?}, Gram–Schmidt {gs:?}");
        qr
    }

    #[test]
    fn qr_keeps_the_columns_gram_schmidt_kept_on_the_calibration_tests_data() {
        let planar = NominalModel::planar(&[1.0, 0.5, 0.3]).unwrap();
        let planar_joints: Vec<f64> = (0..60).flat_map(|i| [0.1 * i as f64, 1.0 - 0.07 * i as f64, 0.3 * (i as f64).sin()]).collect();
        // No ties on the planar arm: the very same columns.
        let (jac, _) = identification_jacobian(&planar, &planar_joints).unwrap();
        let mut colnorm = vec![0.0; jac.ncols()];
        column_scales(&jac, &mut colnorm);
        let all: Vec<usize> = (0..jac.ncols()).collect();
        assert_eq!(independent_columns(jac.as_ref(), &colnorm, &all, 1e-9), gram_schmidt_reference(jac.as_ref(), &colnorm, &all, 1e-9));
        let mut cases = vec![(planar, planar_joints)];
        for conv in [DhConvention::Standard, DhConvention::Modified] {
            let model = NominalModel::DhChain(ur5_like(conv));
            for (count, seed) in [(150, 1), (120, 3), (7, 4)] {
                let joints = sample(&model, count, seed).joints;
                cases.push((model.clone(), joints));
            }
        }
        for (model, joints) in cases {
            let (jac, identifiable) = identification_jacobian(&model, &joints).unwrap();
            let mut colnorm = vec![0.0; jac.ncols()];
            column_scales(&jac, &mut colnorm);
            let all: Vec<usize> = (0..jac.ncols()).collect();
            let tol = DhCalibrationOptions::default().redundancy_tolerance;
            same_rank_and_span(jac.as_ref(), &colnorm, &all, tol);
            // Diagnose's use: unit-scaled nonzero columns, its looser tolerance.
            let norms: Vec<f64> = (0..jac.ncols()).map(|k| (0..jac.nrows()).map(|i| jac[(i, k)].powi(2)).sum::<f64>().sqrt()).collect();
            let nonzero: Vec<usize> = all.iter().copied().filter(|&k| norms[k] > 0.0).collect();
            same_rank_and_span(jac.as_ref(), &norms, &nonzero, 1e-5);
            assert!(!identifiable.is_empty());
        }
    }

    #[test]
    fn rank_is_decided_by_the_relative_tolerance() {
        // Columns e1, e1 + t e2 (t sticks out of e1 by t/√(1+t²) of its length), 0, 2 e1.
        for (t, kept) in [(1e-3, vec![0, 1]), (1e-8, vec![0])] {
            let jac = Mat::from_fn(3, 4, |i, j| match (i, j) {
                (0, 0) | (0, 1) => 1.0,
                (1, 1) => t,
                (0, 3) => 2.0,
                _ => 0.0,
            });
            let norms: Vec<f64> = (0..4).map(|k| (0..3).map(|i| jac[(i, k)] * jac[(i, k)]).sum::<f64>().sqrt()).collect();
            let got = independent_columns(jac.as_ref(), &norms, &[0, 1, 3], 1e-6);
            assert_eq!(got.len(), kept.len(), "t = {t}: {got:?}");
            assert!(!got.contains(&2));
        }
        assert!(independent_columns(Mat::<f64>::zeros(0, 2).as_ref(), &[1.0, 1.0], &[0, 1], 1e-6).is_empty());
    }

    #[test]
    fn qr_keeps_the_columns_gram_schmidt_kept_on_the_diagnose_library() {
        use crate::diagnose::library::{candidate_groups, jacobian, LibraryOptions};
        let six = NominalModel::DhChain(ur5_like(DhConvention::Standard));
        let rr = crate::nominal::planar::as_dh(&crate::simulate::rr::nominal());
        for (model, m) in [(six.clone(), 3), (rr, 2)] {
            let n = model.n_joints();
            let mut data = sample(&six, 40, 11);
            data.n_joints = n;
            data.task_dim = m;
            data.joints = data.joints.chunks_exact(6).flat_map(|q| q[..n].to_vec()).collect();
            data.positions = vec![0.0; 40 * m];
            let params: Vec<_> = candidate_groups(&model, &LibraryOptions::default(), m).into_iter().flat_map(|g| g.params).collect();
            let jac = jacobian(&model, &data, &params);
            let norms: Vec<f64> = (0..jac.ncols()).map(|k| (0..jac.nrows()).map(|i| jac[(i, k)].powi(2)).sum::<f64>().sqrt()).collect();
            let nonzero: Vec<usize> = (0..jac.ncols()).filter(|&k| norms[k] > 1e-9).collect();
            let qr = same_rank_and_span(jac.as_ref(), &norms, &nonzero, 1e-5);
            assert!(qr.len() > 10 && qr.len() < nonzero.len(), "{n} joints: {} of {}", qr.len(), nonzero.len());
        }
    }
}

//! The geometric group as explicit basis functions of CbD's linearised model (Rasmussen & Williams
//! §2.7): r = G β + f + e with β ~ N(0, I), so the covariance gains G Gᵀ and the evidence of "CbD with
//! the geometry calibrated" is scored on the same rows as "CbD on the nominal" (docs/DESIGN.md §3).

use crate::data::Measurements;
use crate::parametric::LinearisedGroup;
use cbd_protocol::Normalisation;
use faer::Mat;

/// Prior standard deviation of each geometric parameter: a length 1 % of the workspace's RMS radius
/// (the task normalisation's scale), an angle 0.01 rad (0.57°). Broad against real arms' errors
/// (tenths of a millimetre, hundredths of a degree), so the data decide what each parameter is;
/// its width only sets the Occam price each parameter pays (ln of prior over posterior width).
pub const GEOMETRY_PRIOR_STD: f64 = 0.01;

/// Whether a parameter of `nominal::dh_parameters` is a length (else an angle in radians).
pub fn is_length(name: &str) -> bool {
    (name.starts_with('a') && !name.starts_with("alpha"))
        || name.starts_with('d')
        || name.starts_with("base_t")
        || name.starts_with("tool_t")
}

/// The group's columns and shift per data row, in the evidence's normalised units.
#[derive(Debug, Clone)]
pub struct GeometricBasis {
    /// Parameters p (columns).
    pub(crate) p: usize,
    pub(crate) m: usize,
    /// G = J D / scale, D the prior standard deviations: (rows · m) × p, row-major.
    pub(crate) columns: Vec<f64>,
    /// J p̂ / scale per row and coordinate: the residual of the fitted chain plus this is the
    /// nominal's to first order, the prior centred on the nominal.
    pub(crate) shift: Vec<f64>,
    pub names: Vec<String>,
}

impl GeometricBasis {
    /// The basis of `group` (linearised on `data`'s rows) for the normalisation `norm`.
    pub fn new(group: &LinearisedGroup, data: &Measurements, norm: &Normalisation) -> Self {
        let (rows, p) = (group.jacobian.nrows(), group.jacobian.ncols());
        // The prior of a length is GEOMETRY_PRIOR_STD internal units; of an angle, that many radians.
        let std: Vec<f64> =
            group.names.iter().map(|n| if is_length(n) { norm.length_to_user(GEOMETRY_PRIOR_STD) } else { GEOMETRY_PRIOR_STD }).collect();
        let columns = (0..rows)
            .flat_map(|i| (0..p).map(move |k| (i, k)))
            .map(|(i, k)| norm.length_to_internal(group.jacobian[(i, k)] * std[k]))
            .collect();
        debug_assert_eq!(rows, data.len() * data.task_dim);
        let shift = group.shift.iter().map(|v| norm.length_to_internal(*v)).collect();
        GeometricBasis { p, m: data.task_dim, columns, shift, names: group.names.clone() }
    }

    /// The rows at `indices` (as `Measurements::subset`).
    pub(crate) fn subset(&self, indices: &[usize]) -> Self {
        let (m, p) = (self.m, self.p);
        let columns = indices.iter().flat_map(|&i| self.columns[i * m * p..(i + 1) * m * p].iter().copied()).collect();
        let shift = indices.iter().flat_map(|&i| self.shift[i * m..(i + 1) * m].iter().copied()).collect();
        GeometricBasis { p, m, columns, shift, names: self.names.clone() }
    }

    /// G as a matrix, (rows · m) × p.
    pub(crate) fn matrix(&self) -> Mat<f64> {
        let rows = self.columns.len() / self.p.max(1);
        Mat::from_fn(rows, self.p, |i, k| self.columns[i * self.p + k])
    }

    /// G's rows of coordinate `c`: rows × p.
    pub(crate) fn coordinate(&self, c: usize) -> Mat<f64> {
        let rows = self.shift.len() / self.m;
        Mat::from_fn(rows, self.p, |i, k| self.columns[(i * self.m + c) * self.p + k])
    }
}

#[cfg(test)]
mod tests {
    use super::super::search::Criterion;
    use super::super::table::{PairTable, Theta};
    use super::*;
    use crate::parametric::{calibrate_dh, linearised_group, DhCalibrationOptions};
    use crate::simulate::six_joint::{random_configurations, SixJointRobot};
    use faer::linalg::solvers::Solve;

    /// The evidence with the explicit basis against the matrix determinant lemma on the plain
    /// covariance K (R&W §2.7): log N(r | 0, K + G Gᵀ) = log N(r | 0, K) − ½ ln|A| + ½ bᵀA⁻¹b with
    /// A = I + GᵀK⁻¹G, b = GᵀK⁻¹r — an independent route to the same number, on the six-joint arm.
    #[test]
    fn explicit_basis_evidence_follows_the_determinant_lemma() {
        let robot = SixJointRobot::ur5_like(3);
        let nominal = robot.nominal.clone();
        let data = robot.measure(&random_configurations(40, 5), 9);
        let norm = data.normalisation();
        let fit = calibrate_dh(&nominal, &data, &DhCalibrationOptions::default()).unwrap();
        let group = linearised_group(&nominal, &fit.stats, &data).unwrap();
        let basis = GeometricBasis::new(&group, &data, &norm);
        assert!(basis.p > 20, "{} parameters", basis.p);
        let theta =
            Theta { log_widths: vec![0.3f64.ln(); 6], log_gamma_v: -9.0, log_a: 0.5, log_gamma_w: -12.0, log_sigma: -9.0, config: None };
        let with = PairTable::new(&fit.model, &data, &norm).with_geometry(&basis);
        let mut plain = PairTable::new(&fit.model, &data, &norm);
        for (r, s) in plain.residual.iter_mut().zip(&basis.shift) {
            *r += s;
        }
        let (nlml_with, _) = with.nlml_and_gradient(&theta.pack()).unwrap();
        let (nlml_plain, _) = plain.nlml_and_gradient(&theta.pack()).unwrap();
        let (k, _, _, _) = plain.covariance(&theta);
        let llt = k.llt(faer::Side::Lower).unwrap();
        let g = basis.matrix();
        let k_inv_g = llt.solve(&g);
        let r = faer::Mat::from_fn(plain.residual.len(), 1, |i, _| plain.residual[i]);
        let b = g.transpose() * llt.solve(&r);
        let a = faer::Mat::<f64>::identity(basis.p, basis.p) + g.transpose() * &k_inv_g;
        let a_llt = a.llt(faer::Side::Lower).unwrap();
        let logdet_a: f64 = 2.0 * (0..basis.p).map(|i| a_llt.L()[(i, i)].ln()).sum::<f64>();
        let quad = (b.transpose() * a_llt.solve(&b))[(0, 0)];
        let expected = nlml_plain + 0.5 * logdet_a - 0.5 * quad;
        assert!((nlml_with - expected).abs() <= 1e-6 * expected.abs().max(1.0), "explicit basis {nlml_with} vs lemma {expected}");
    }

    #[test]
    fn lengths_and_angles_are_told_apart() {
        for (name, length) in [
            ("a3", true),
            ("alpha3", false),
            ("d1", true),
            ("theta_offset2", false),
            ("base_tx", true),
            ("base_rz", false),
            ("tool_tz", true),
            ("tool_rx", false),
        ] {
            assert_eq!(is_length(name), length, "{name}");
        }
    }
}

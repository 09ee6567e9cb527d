//! A blob's own prior: the θ its hyperparameters stand for (the inverse of
//! [`super::CbdHyperparameters::to_internal`]) and the covariance K_lin + σ² I of CbD's linearised
//! model (docs/DESIGN.md §3) on any rows, evaluated by the evidence's own [`PairTable::covariance`]
//! — what `cbd check` conditions on the blob's measurement points (docs/DESIGN.md "cbd check").

use super::table::{ConfigTheta, PairTable, Theta};
use crate::data::Measurements;
use cbd_protocol::Model;
use faer::Mat;

/// log a_C of a flat configuration task factor (K̃_X = 1): 1/(2 a_C²) = ½ e⁻¹⁴⁰⁰ underflows to 0.
const FLAT_LOG_A: f64 = 700.0;

impl Theta {
    /// The blob's θ (logarithms, its normalised units). The blob keeps the kernels relative to the
    /// task field's amplitude — γ = γ_V/γ_W, γ_C/γ_W, its `sigma` = σ/√γ_W (data units) — and σ
    /// itself (`noise_sigma`, data units, format 7), so γ_W = (σ / sigma)² and every amplitude
    /// follows. `None` without σ (format 6 or older) or with a non-positive value.
    pub(super) fn from_blob(model: &Model) -> Option<Theta> {
        let sigma = model.noise_sigma?;
        let norm = &model.normalisation;
        if !(sigma > 0.0 && model.sigma > 0.0 && model.joint_kernel.gamma > 0.0 && model.task_kernel.width > 0.0) {
            return None;
        }
        // γ_W (data units) = (σ / (σ/√γ_W))², then normalised: v / s².
        let gamma_w = norm.variance_to_internal((sigma / model.sigma).powi(2));
        let log_params = |axes: &[cbd_protocol::JointKernelAxis]| -> Vec<f64> {
            axes.iter().map(|a| crate::axis_forms::form_and_parameter(a).1.ln()).collect()
        };
        let theta = Theta {
            log_widths: log_params(&model.joint_kernel.axes),
            log_gamma_v: (model.joint_kernel.gamma * gamma_w).ln(),
            log_a: model.task_kernel.width.ln(),
            log_gamma_w: gamma_w.ln(),
            log_sigma: norm.length_to_internal(sigma).ln(),
            config: model.configuration_kernel.as_ref().map(|c| ConfigTheta {
                log_widths: log_params(&c.axes),
                log_a: c.task_width.map_or(FLAT_LOG_A, f64::ln),
                log_gamma: (c.gamma * gamma_w).ln(),
            }),
        };
        let finite = theta.pack().iter().all(|v| v.is_finite());
        finite.then_some(theta)
    }
}

/// K_lin + σ² I of the blob's linearised model on `rows` (the blob's nominal chain, its
/// normalisation, its θ: [`Theta::from_blob`]), internal units, (rows · m)². With `geometry`
/// (the blob's chain is a DH-calibrated one), + G Gᵀ: the geometric group's identifiable
/// parameters at the blob's chain as explicit basis functions with the evidence's prior
/// ([`super::GeometricBasis`], docs/DESIGN.md §3 "The geometry choice"), so that conditioning on
/// the blob's points leaves the fitted geometry's own uncertainty in the prediction. `None` when
/// the blob records no σ.
pub(crate) fn blob_covariance(model: &Model, rows: &Measurements, geometry: bool) -> Option<Mat<f64>> {
    let theta = Theta::from_blob(model)?;
    let mut table = PairTable::new(&model.nominal, rows, &model.normalisation);
    if let (true, Some(group)) = (geometry, geometric_group(&model.nominal, rows)) {
        table = table.with_geometry(&super::GeometricBasis::new(&group, rows, &model.normalisation));
    }
    Some(table.covariance(&theta).0)
}

/// The geometric group of `chain` linearised at the chain itself (no change from it) on `rows`.
fn geometric_group(chain: &cbd_protocol::NominalModel, rows: &Measurements) -> Option<crate::parametric::LinearisedGroup> {
    let cbd_protocol::NominalModel::DhChain(dh) = &crate::nominal::planar::as_dh(chain) else { return None };
    let names = crate::nominal::dh_parameters::parameter_names_for(dh);
    let stats = crate::parametric::DhFitStats {
        iterations: 0,
        initial_rms: 0.0,
        final_rms: 0.0,
        n_parameters: names.len(),
        rank: names.len(),
        unidentifiable: Vec::new(),
        parameter_changes: vec![0.0; names.len()],
        parameter_names: names,
        converged: true,
        redundant_at_nominal: Vec::new(),
    };
    crate::parametric::linearised_group(chain, &stats, rows)
}

/// A blob of `nominal` whose control points are `points` (row-major configurations), with unit
/// kernels, σ = 0.01 and zero momenta: for tests that set the fields they need.
#[cfg(test)]
pub(crate) fn model_for_tests(nominal: cbd_protocol::NominalModel, points: &[f64]) -> Model<'static> {
    use cbd_protocol::F64Slice;
    let (n, m) = (nominal.n_joints(), nominal.task_dim());
    let count = points.len() / n;
    let points: &'static [u8] = Box::leak(cbd_protocol::f64_le_bytes(points).into_boxed_slice());
    let momenta: &'static [u8] = Box::leak(cbd_protocol::f64_le_bytes(&vec![0.0; count * m]).into_boxed_slice());
    Model {
        n_points: count as u32,
        joint_kernel: cbd_protocol::JointKernel { gamma: 1.0, axes: crate::axis_forms::default_axes(&nominal).into_iter().collect() },
        nominal,
        normalisation: cbd_protocol::Normalisation { task_offset: [0.0; 3], task_scale: 1.0 },
        task_kernel: cbd_protocol::TaskKernel { width: 1.0 },
        integrator: cbd_protocol::Integrator { method: cbd_protocol::IntegratorMethod::Euler, steps: 1 },
        momentum_law: cbd_protocol::MomentumLaw::Hamiltonian,
        sigma: 1.0,
        points: F64Slice::from_le_bytes(points),
        momenta: F64Slice::from_le_bytes(momenta),
        expansion: None,
        noise_sigma: Some(0.01),
        configuration_kernel: None,
        drift: None,
        provenance: None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::evidence::CbdHyperparameters;
    use cbd_protocol::{ConfigurationKernel, JointKernelAxis, Normalisation};

    /// Hyperparameters in the data's units → the blob's fields (`to_internal`, as `cbd fit` writes
    /// them) → θ here lands on θ from the same hyperparameters by the evidence's own `from_user`.
    #[test]
    fn the_blob_theta_is_the_evidence_theta_of_its_hyperparameters() {
        let norm = Normalisation { task_offset: [3.0, -1.0, 0.5], task_scale: 250.0 };
        let user = CbdHyperparameters {
            joint_axes: vec![JointKernelAxis::Periodic { b: 0.7 }, JointKernelAxis::Gaussian { width: 30.0 }],
            joint_gamma: 3e-7,
            task_width: 120.0,
            task_gamma: 2e-3,
            sigma: 0.02,
            configuration: Some(crate::evidence::ConfigurationHyperparameters {
                joint_axes: vec![JointKernelAxis::Periodic { b: 2.0 }, JointKernelAxis::Gaussian { width: 5.0 }],
                task_width: Some(80.0),
                gamma: 4e-4,
            }),
        };
        let flow = user.to_internal(&norm);
        let mut model = model_for_tests(cbd_protocol::NominalModel::planar(&[1.0, 0.5]).unwrap(), &[0.0; 2]);
        model.normalisation = norm.clone();
        model.joint_kernel = flow.joint_kernel;
        model.task_kernel = flow.task_kernel;
        model.sigma = flow.sigma;
        model.configuration_kernel = flow.configuration_kernel;
        model.noise_sigma = Some(user.sigma);
        let from_blob = Theta::from_blob(&model).unwrap().pack();
        let expected = Theta::from_user(&user, &norm, FLAT_LOG_A).pack();
        assert_eq!(from_blob.len(), expected.len());
        for (k, (a, b)) in from_blob.iter().zip(&expected).enumerate() {
            assert!((a - b).abs() <= 1e-12 * b.abs().max(1.0), "θ[{k}]: blob {a} vs evidence {b}");
        }
        // Flat configuration task factor; no σ (format 6) gives no θ.
        model.configuration_kernel = Some(ConfigurationKernel { task_width: None, ..model.configuration_kernel.clone().unwrap() });
        assert_eq!(Theta::from_blob(&model).unwrap().config.unwrap().log_a, FLAT_LOG_A);
        model.noise_sigma = None;
        assert!(Theta::from_blob(&model).is_none());
    }
}

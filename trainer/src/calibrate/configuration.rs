//! The configuration-dependent task field (docs/DESIGN.md §16, Trainer): whether the model has it
//! (`--configuration-field auto|off|on`), and its fit. The geometry is decided first with CbD's
//! plain prior; the term is then searched on the chosen base's residual, compared with the plain
//! model on the same rows ([`crate::evidence::search_configuration_term`]), and, when kept, fitted as
//! the blob format allows it: Euler × 1, the kernel form (no scheme choice, no expansion).

use super::hyperparameters::options_for;
use super::{scheme::SchemeChoice, ConfigurationField, Settings};
use crate::data::stage_rows::StageRows;
use crate::data::Measurements;
use crate::evidence::{search_configuration_term, CbdHyperparameters, ConfigurationEvidence};
use crate::solver::{fit_cbd, CbdFit, CbdOptions};
use cbd_protocol::{Integrator, IntegratorMethod, NominalModel, Normalisation};

/// The comparison, when it runs: with `auto` and `on` wherever CbD's evidence chose `plain`.
pub fn choose(
    base: &NominalModel,
    data: &StageRows,
    norm: &Normalisation,
    settings: &Settings,
    plain: &CbdHyperparameters,
    searched: bool,
) -> crate::Result<Option<ConfigurationEvidence>> {
    // A scheme given other than Euler × 1 leaves `auto` without the term (the format evaluates it with
    // Euler × 1 only); `on` refuses it.
    let other_scheme = settings.integrator.is_some_and(|m| m != IntegratorMethod::Euler) || settings.steps.is_some_and(|s| s != 1);
    match (settings.configuration, searched) {
        (ConfigurationField::Off, _) | (ConfigurationField::Auto, false) => Ok(None),
        (ConfigurationField::Auto, true) if other_scheme => Ok(None),
        (ConfigurationField::On, true) if other_scheme => Err(scheme_refused()),
        (ConfigurationField::On, false) => Err(crate::Error::InvalidInput(
            "--configuration-field on: the field's hyperparameters come from CbD's evidence, which does not run here (the paper's values, or every value given)".into(),
        )),
        (_, true) => Ok(Some(search_configuration_term(base, &data.rows, &data.evidence, norm, &settings.evidence, plain)?)),
    }
}

/// The fit with the term: Euler × 1 (the only scheme the blob evaluates it with), the kernel form.
pub fn fit(
    base: &NominalModel,
    data: &Measurements,
    h: &CbdHyperparameters,
    norm: &Normalisation,
    settings: &Settings,
) -> crate::Result<(SchemeChoice, CbdOptions, CbdFit)> {
    let integrator = Integrator { method: IntegratorMethod::Euler, steps: 1 };
    if settings.integrator.is_some_and(|m| m != IntegratorMethod::Euler) || settings.steps.is_some_and(|s| s != 1) {
        return Err(scheme_refused());
    }
    let scheme = SchemeChoice {
        integrator,
        chosen_by: "the configuration field: Euler × 1 only (blob format 8), no cross-validation".into(),
        cross_validation: vec![],
    };
    let options = options_for(h, norm, integrator, settings);
    let fit = fit_cbd(base, data, &options)?;
    Ok((scheme, options, fit))
}

/// `--configuration-field on` with a scheme the format does not evaluate the term with.
fn scheme_refused() -> crate::Error {
    crate::Error::InvalidInput(
        "--configuration-field on: the configuration field is evaluated with Euler × 1 only (blob format 8); drop --integrator/--steps or use --configuration-field auto|off".into(),
    )
}

/// Whether `fit`'s blob carries its fields in the kernels' own basis (an expansion): its kernel form
/// cancels, which the configuration field's kernel form would share.
pub fn needs_expansion(fit: &CbdFit) -> bool {
    fit.report.expansion.is_some()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The planar RR arm: the closed form with the term reproduces its own K_lin solve, and with
    /// γ_C → 0 the fit's momenta are the plain closed form's.
    #[test]
    fn the_terms_closed_form_reduces_to_the_plain_one() {
        use crate::simulate::{configurations, rr, Sampling};
        use cbd_protocol::{ConfigurationKernel, JointKernelAxis, MomentumLaw};
        let data = rr::RealRr::default().measure(&configurations(Sampling::Uniform { count: 30, seed: 3 }, 2));
        let norm = data.normalisation();
        let nominal = rr::nominal();
        let h = crate::calibrate::paper_rr_hyperparameters();
        let mut opts = CbdOptions::new(h.to_internal(&norm), Integrator { method: IntegratorMethod::Euler, steps: 1 }, norm.clone());
        opts.solver.law = MomentumLaw::Hamiltonian;
        let cp = crate::flow::ControlPoints::new(
            &nominal,
            &norm,
            data.joints.clone(),
            opts.joint_kernel.clone(),
            opts.task_kernel,
            opts.solver.law,
            opts.integrator,
        );
        let tiny = ConfigurationKernel {
            gamma: 1e-300,
            axes: heapless::Vec::from_slice(&[JointKernelAxis::Periodic { b: 1.0 }; 2]).unwrap(),
            task_width: None,
        };
        let plain = crate::solver::regulariser::regulariser_matrix(&cp);
        let with = crate::solver::regulariser::k_lin_with_configuration(&cp, &tiny);
        let dim = plain.nrows();
        let worst =
            (0..dim).flat_map(|r| (0..dim).map(move |c| (r, c))).fold(0.0f64, |w, (r, c)| w.max((plain[(r, c)] - with[(r, c)]).abs()));
        assert_eq!(worst, 0.0);
        // A visible term: K_lin grows by γ_C exp(Σ b (cos Δ − 1)) on the diagonal blocks' diagonal only.
        let term = ConfigurationKernel { gamma: 0.5, ..tiny };
        let with = crate::solver::regulariser::k_lin_with_configuration(&cp, &term);
        let (i, j) = (4, 1);
        let (qi, qj) = (data.joints(i), data.joints(j));
        let kq: f64 = (0..2).map(|d| (qi[d] - qj[d]).cos() - 1.0).sum::<f64>().exp();
        assert!((with[(2 * i, 2 * j)] - plain[(2 * i, 2 * j)] - 0.5 * kq).abs() < 1e-15);
        assert_eq!(with[(2 * i, 2 * j + 1)], plain[(2 * i, 2 * j + 1)]);
    }
}

//! CbD's hyperparameters and the fit's options as every stage of the pipeline takes them: the
//! task space's normalisation, the hyperparameters by their source (CbD's evidence, the paper's
//! values) with the hand-given ones applied, and the fit's options for a scheme. The stages
//! (geometry, configuration field, scheme) call these; none calls back into the orchestrator.

use super::{HyperparameterSource, Settings};
use crate::data::stage_rows::StageRows;
use crate::evidence::{choose_on_rows, CbdHyperparameters, Evidence, GeometricBasis};
use crate::solver::{CbdOptions, SolverSettings};
use cbd_protocol::{Integrator, NominalModel, Normalisation};

/// The paper's RR hyperparameters (docs/DESIGN.md §6) in data units: lengths in units of l1 = 1,
/// task kernel with unit amplitude, σ = 1e-6.
pub fn paper_rr_hyperparameters() -> CbdHyperparameters {
    CbdHyperparameters {
        joint_axes: cbd_protocol::paper_rr::joint_kernel().axes.to_vec(),
        joint_gamma: cbd_protocol::paper_rr::JOINT_GAMMA,
        task_width: cbd_protocol::paper_rr::TASK_WIDTH,
        task_gamma: 1.0,
        sigma: 1e-6,
        configuration: None,
    }
}

/// The fit's options for hyperparameters `h`, normalisation `norm` and scheme `integrator`.
pub fn options_for(h: &CbdHyperparameters, norm: &Normalisation, integrator: Integrator, settings: &Settings) -> CbdOptions {
    let mut opts = CbdOptions::new(h.to_internal(norm), integrator, norm.clone());
    // The paper's reproduction keeps the paper's form, momenta, unless asked otherwise.
    let representation = match (settings.source, settings.solver.representation) {
        (HyperparameterSource::PaperRr, crate::expansion::Representation::Auto) => crate::expansion::Representation::Kernel,
        (_, r) => r,
    };
    // The configuration field is evaluated in the kernel form only (blob format 8).
    let representation = if h.configuration.is_some() { crate::expansion::Representation::Kernel } else { representation };
    opts.solver = SolverSettings { representation, ..settings.solver };
    // Recorded in the blob (format 7): what `cbd eval` sets a table's noise floor by.
    opts.noise_sigma = Some(h.sigma);
    opts
}

/// CbD's hyperparameters for `base` on `data`: the source's (its own evidence on the evidence's rows
/// — with the geometric group `geometry` marginalised when given —, or the paper's), then the
/// hand-given values.
pub fn choose_cbd_hyperparameters_with_overrides(
    base: &NominalModel,
    data: &StageRows,
    norm: &Normalisation,
    settings: &Settings,
    geometry: Option<&GeometricBasis>,
) -> crate::Result<(CbdHyperparameters, Option<Evidence>)> {
    let (mut h, evidence) = match settings.source {
        HyperparameterSource::PaperRr => (paper_rr_hyperparameters(), None),
        // Every value is given: no search (the placeholder's fields are all replaced below).
        HyperparameterSource::Evidence if settings.overrides.is_complete(base) => (placeholder_hyperparameters(base), None),
        HyperparameterSource::Evidence => {
            let e = choose_on_rows(base, &data.rows, &data.evidence, norm, &settings.evidence, geometry)?;
            (e.hyperparameters.clone(), Some(e))
        }
    };
    h = settings.overrides.apply(base, h);
    Ok((h, evidence))
}

/// One axis per joint of `base`, for overrides that replace every field.
fn placeholder_hyperparameters(base: &NominalModel) -> CbdHyperparameters {
    let mut h = paper_rr_hyperparameters();
    h.joint_axes = crate::axis_forms::default_axes(base);
    h
}

/// The task-space normalisation for `settings`: the rows' own (`rows`: [`StageRows::normalisation`],
/// RMS radius) or none (the paper's units).
pub fn normalisation_for(rows: &Normalisation, settings: &Settings) -> Normalisation {
    match settings.source {
        HyperparameterSource::PaperRr => Normalisation::IDENTITY,
        HyperparameterSource::Evidence => rows.clone(),
    }
}

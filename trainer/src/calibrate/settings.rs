//! What a user can set for a calibration; anything unset is chosen by the pipeline.

use crate::evidence::{CbdHyperparameters, EvidenceOptions};
use crate::solver::SolverSettings;
use cbd_protocol::{IntegratorMethod, JointKernelAxis, NominalModel};

/// Where the hyperparameters come from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum HyperparameterSource {
    /// CbD's own evidence on the training rows (the default everywhere).
    Evidence,
    /// The paper's RR values (docs/DESIGN.md §6), task space not normalised: the demo's reproduction.
    PaperRr,
}

/// Hand-given hyperparameters, data units; each replaces the chosen value of that one.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Overrides {
    /// σ, noise per coordinate (data length unit).
    pub sigma: Option<f64>,
    /// a, task kernel width (data length unit).
    pub task_width: Option<f64>,
    /// γ_W, task field variance (data length unit squared).
    pub task_gamma: Option<f64>,
    /// b of every periodic (revolute) joint axis.
    pub joint_b: Option<f64>,
    /// γ_V, joint field variance (rad²).
    pub joint_gamma: Option<f64>,
}

impl Overrides {
    /// Whether every hyperparameter of `base` is given (then no search runs).
    pub fn is_complete(&self, base: &NominalModel) -> bool {
        self.sigma.is_some()
            && self.task_width.is_some()
            && self.task_gamma.is_some()
            && self.joint_gamma.is_some()
            && self.joint_b.is_some()
            && (0..base.n_joints()).all(|d| base.is_revolute(d))
    }

    pub fn apply(&self, base: &NominalModel, mut h: CbdHyperparameters) -> CbdHyperparameters {
        if let Some(v) = self.sigma {
            h.sigma = v;
        }
        if let Some(v) = self.task_width {
            h.task_width = v;
        }
        if let Some(v) = self.task_gamma {
            h.task_gamma = v;
        }
        if let Some(v) = self.joint_gamma {
            h.joint_gamma = v;
        }
        if let Some(b) = self.joint_b {
            for (d, axis) in h.joint_axes.iter_mut().enumerate() {
                if base.is_revolute(d) {
                    *axis = JointKernelAxis::Periodic { b };
                }
            }
        }
        h
    }
}

/// Whether the model has the configuration-dependent task field (docs/DESIGN.md §16).
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ConfigurationField {
    /// Decided by CbD's evidence: kept when it gains more than ½ ln(N m) nats per added hyperparameter.
    Auto,
    /// CbD's two fields only.
    Off,
    /// Always (its hyperparameters by evidence; Euler × 1, kernel form).
    On,
}

/// Everything besides the data that defines a calibration.
#[derive(Debug, Clone, PartialEq)]
pub struct Settings {
    pub source: HyperparameterSource,
    pub overrides: Overrides,
    pub evidence: EvidenceOptions,
    /// Fixed scheme; `None` for either part: chosen by cross-validation (method Euler).
    pub integrator: Option<IntegratorMethod>,
    pub steps: Option<u16>,
    /// Folds of the scheme's cross-validation.
    pub scheme_folds: usize,
    /// Deform the nominal chain, or calibrate its geometric group (DH parameters, base, tool) first
    /// and deform that; `Auto` (the default): whichever CbD's evidence scores higher.
    pub geometry: super::Geometry,
    /// The configuration-dependent task field: by evidence (`Auto`, the default), off or on.
    pub configuration: ConfigurationField,
    /// How the fit runs (law, iterations, method, threads, representation, memory budget,
    /// verbosity): the fit's own options take it whole (`options_for`), but for the paper's
    /// reproduction, which keeps the momenta when the representation is `Auto`.
    pub solver: SolverSettings,
    /// The drift test in measurement order, beside the field's search (`cbd fit`'s), or none.
    pub drift: Option<super::drift_test::DriftOptions>,
}

impl Settings {
    /// The cuts of the rows the stages take with these settings (`data::stage_rows`).
    pub fn cuts(&self) -> crate::data::stage_rows::Cuts {
        crate::data::stage_rows::Cuts {
            evidence_unknowns: self.evidence.max_unknowns,
            coarse_unknowns: self.evidence.coarse_unknowns,
            folds: self.scheme_folds.max(2),
            drift_window: self.drift.map(|d| d.window),
        }
    }

    /// Whether CbD's hyperparameters for `base` come from a search of its evidence (not the
    /// paper's values, nor every value given).
    pub fn searches_evidence(&self, base: &NominalModel) -> bool {
        self.source == HyperparameterSource::Evidence && !self.overrides.is_complete(base)
    }
}

impl Default for Settings {
    fn default() -> Self {
        Settings {
            source: HyperparameterSource::Evidence,
            overrides: Overrides::default(),
            evidence: EvidenceOptions::default(),
            integrator: None,
            steps: None,
            scheme_folds: 4,
            geometry: super::Geometry::Auto,
            configuration: ConfigurationField::Auto,
            solver: SolverSettings::default(),
            drift: None,
        }
    }
}

//! Poses for `cbd check` (`cbd plan --check`, issue 50 item 5): those that make the check most
//! sensitive to the changes it names, and the smallest change of each kind it detects with them
//! and with as many random poses (`plan::check`).

use super::plan::{check_finite_limits, maps_joints};
use super::{ArmModel, DecodedBlob};
use crate::error::{Error, Result};

/// What a check's plan is asked: its poses, candidates and level.
#[derive(Debug, Clone)]
pub struct CheckPlanSettings {
    /// Poses the check will measure.
    pub count: usize,
    /// Random candidates within the joint limits.
    pub candidates: usize,
    pub seed: u64,
    /// The check's level.
    pub alpha: f64,
    /// The check registers the fresh rows' frame (`cbd check --register`; also when the model
    /// file's base is `register = true`).
    pub register: bool,
}

impl CheckPlanSettings {
    /// Rejects out-of-range values before any work, naming the flag.
    pub fn validate(&self) -> Result<()> {
        if self.count == 0 {
            return Err(Error::InvalidInput("--check must be at least 1".into()));
        }
        if !(self.alpha > 0.0 && self.alpha < 1.0) {
            return Err(Error::InvalidInput(format!(
                "--alpha must be a number between 0 and 1 (exclusive), got {}",
                crate::error::number(self.alpha)
            )));
        }
        Ok(())
    }
}

/// A check's plan: its poses and the smallest change of each kind it detects.
pub struct CheckPlan {
    pub plan: crate::plan::check::CheckPlan,
    /// The check's poses and level, as asked.
    count: usize,
    alpha: f64,
    n_joints: usize,
    /// Each joint column's factor from the file's units to the model's.
    joint_factor: Vec<f64>,
    unit: &'static str,
}

/// Plans `settings.count` poses for a check of `blob` (fitted with `arm`'s model file, recording
/// its σ); what it planned is said on the message channel.
pub fn plan_check(arm: &ArmModel, blob: DecodedBlob<'_>, settings: &CheckPlanSettings) -> Result<CheckPlan> {
    settings.validate()?;
    check_finite_limits(arm)?;
    let (model, blob_path, spec) = (&blob.model, blob.source, &arm.spec);
    if super::blob_rows::recorded_sigma(model, blob_path)?.is_none() {
        return Err(Error::InvalidInput(format!("{}: {}", blob_path.display(), crate::evaluation::check::CheckError::NoSigma)));
    }
    let columns = crate::data::joint_columns::JointColumns::new(spec);
    let joint_factor = columns.factors().to_vec();
    let to_model = |c: &[f64]| -> Vec<f64> { columns.to_model_from_model_units(c) };
    let unit = spec.model_length_unit.name();
    let input = crate::plan::check::CheckPlanInput {
        model,
        geometry: model.nominal != arm.nominal,
        limits: &spec.joint_limits,
        to_model: if maps_joints(spec) { Some(&to_model) } else { None },
        count: settings.count,
        candidates: settings.candidates,
        seed: settings.seed,
        alpha: settings.alpha,
        register: settings.register || arm.register_base(),
        unit,
    };
    let result = crate::plan::check::plan_check(&input).map_err(|e| Error::InvalidInput(format!("{}: {e}", blob_path.display())))?;
    errln!(
        "planned {} check poses from {} candidates ({} within 1° of a singular configuration left out) in {:.2} s",
        settings.count,
        result.candidates,
        result.rejected_singular,
        result.seconds
    );
    Ok(CheckPlan { plan: result, count: settings.count, alpha: settings.alpha, n_joints: model.n_joints(), joint_factor, unit })
}

impl CheckPlan {
    /// The planned poses as the controller's values, in the model file's joint units.
    pub fn poses_in_file_units(&self) -> Vec<Vec<f64>> {
        let poses = self.plan.controller.chunks_exact(self.n_joints);
        poses.map(|pose| pose.iter().zip(&self.joint_factor).map(|(c, f)| c / f).collect()).collect()
    }

    /// The table `cbd plan --check` prints: the smallest change of each kind the check detects.
    pub fn table(&self) -> Vec<String> {
        let result = &self.plan;
        let mut lines = vec![
            format!(
                "smallest change the check detects at alpha = {} with {:.0} % power ({} degrees of freedom, noncentrality {:.2}), {} poses:",
                self.alpha,
                100.0 * result.power,
                result.dof,
                result.noncentrality,
                self.count
            ),
            format!("{:<26} {:>12} {:>12} {:>8}  unit", "change", "random", "planned", "ratio"),
        ];
        for s in &result.sizes {
            lines.push(format!(
                "{:<26} {:>12.4e} {:>12.4e} {:>8.2}  {}",
                s.effect,
                s.random,
                s.planned,
                s.random / s.planned,
                if s.unit.is_empty() { "(ratio)" } else { &s.unit }
            ));
        }
        if !result.framed.is_empty() {
            lines.push(format!("taken up by the registered frame (no size detects them): {}", result.framed.join(", ")));
        }
        if !result.invisible.is_empty() {
            lines.push(format!("not seen at the measured point (no size detects them): {}", result.invisible.join(", ")));
        }
        lines
    }

    /// `cbd plan --check --json`'s value.
    pub fn to_json(&self) -> serde_json::Value {
        let result = &self.plan;
        serde_json::json!({
            "length_unit": self.unit,
            "check_poses": self.count,
            "alpha": result.alpha,
            "power": result.power,
            "dof": result.dof,
            "noncentrality": result.noncentrality,
            "random_sets": crate::plan::check::RANDOM_SETS,
            "sizes": result.sizes,
            "not_seen": result.invisible,
            "taken_up_by_the_frame": result.framed,
            "candidates": result.candidates,
            "rejected_singular": result.rejected_singular,
            "poses": result.controller.chunks_exact(self.n_joints).map(|p| p.to_vec()).collect::<Vec<_>>(),
        })
    }
}

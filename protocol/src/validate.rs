//! Consistency checks run on every encode and decode.

use crate::model::*;

/// What is wrong with a model, naming the field.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ModelError {
    /// A field holds NaN or ±∞.
    NonFinite { field: &'static str, index: usize },
    /// A field is outside its allowed range (e.g. a width ≤ 0).
    OutOfRange { field: &'static str },
    /// Array or table sizes disagree.
    Dimension { field: &'static str, expected: usize, found: usize },
}

impl core::fmt::Display for ModelError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            ModelError::NonFinite { field, index } => write!(f, "field `{field}` has a non-finite value at index {index}"),
            ModelError::OutOfRange { field } => write!(f, "field `{field}` is out of range"),
            ModelError::Dimension { field, expected, found } => {
                write!(f, "field `{field}` has size {found}, expected {expected}")
            }
        }
    }
}

fn finite(field: &'static str, values: impl IntoIterator<Item = f64>) -> Result<(), ModelError> {
    for (index, v) in values.into_iter().enumerate() {
        if !v.is_finite() {
            return Err(ModelError::NonFinite { field, index });
        }
    }
    Ok(())
}

fn positive(field: &'static str, v: f64) -> Result<(), ModelError> {
    finite(field, [v])?;
    if v > 0.0 {
        Ok(())
    } else {
        Err(ModelError::OutOfRange { field })
    }
}

fn dimension(field: &'static str, expected: usize, found: usize) -> Result<(), ModelError> {
    if expected == found {
        Ok(())
    } else {
        Err(ModelError::Dimension { field, expected, found })
    }
}

impl Model<'_> {
    /// Checks every dimension and value; a model that passes can be evaluated.
    pub fn validate(&self) -> Result<(), ModelError> {
        let n = self.n_joints();
        let m = self.task_dim();
        if n == 0 {
            return Err(ModelError::OutOfRange { field: "nominal.joints" });
        }
        match &self.nominal {
            NominalModel::PlanarChain { lengths, .. } => finite("nominal.lengths", lengths.iter().copied())?,
            NominalModel::DhChain(c) => {
                for j in &c.joints {
                    finite("nominal.joints", [j.a, j.alpha, j.d, j.theta_offset])?;
                }
                for (name, t) in [("nominal.base", &c.base), ("nominal.tool", &c.tool)] {
                    finite(name, t.rotation.iter().chain(t.translation.iter()).copied())?;
                }
            }
        }
        finite("normalisation.task_offset", self.normalisation.task_offset)?;
        positive("normalisation.task_scale", self.normalisation.task_scale)?;
        positive("joint_kernel.gamma", self.joint_kernel.gamma)?;
        dimension("joint_kernel.axes", n, self.joint_kernel.axes.len())?;
        for (d, axis) in self.joint_kernel.axes.iter().enumerate() {
            match *axis {
                JointKernelAxis::Periodic { b } => {
                    positive("joint_kernel.axes.b", b)?;
                    if !self.nominal.is_revolute(d) {
                        return Err(ModelError::OutOfRange { field: "joint_kernel.axes (periodic on a prismatic joint)" });
                    }
                }
                JointKernelAxis::Gaussian { width } => positive("joint_kernel.axes.width", width)?,
            }
        }
        positive("task_kernel.width", self.task_kernel.width)?;
        if self.integrator.steps == 0 || self.integrator.steps > MAX_STEPS {
            return Err(ModelError::OutOfRange { field: "integrator.steps" });
        }
        positive("sigma", self.sigma)?;
        if self.n_points == 0 {
            return Err(ModelError::OutOfRange { field: "n_points" });
        }
        let n_points = self.n_points as usize;
        dimension("points", n_points * n * 8, self.points.byte_len())?;
        dimension("momenta", n_points * m * 8, self.momenta.byte_len())?;
        finite("points", self.points.iter())?;
        finite("momenta", self.momenta.iter())?;
        Ok(())
    }
}

//! CbD's hyperparameters as the user gives and reads them, and the one conversion each way
//! between them and the internal units (docs/DESIGN.md §1, §3): the user's form
//! ([`CbdHyperparameters`], the data's units: what `--sigma`, `--task-width`, … and the JSON mean)
//! goes to the flow's ([`FlowHyperparameters`], normalised: what the fit and the blob use) by
//! [`CbdHyperparameters::to_internal`]; the evidence's search, on θ = the logarithms in normalised
//! units ([`Theta`]), hands its choice back by [`Theta::to_user`].

use super::table::Theta;
use crate::axis_forms::{axes_at, AxisForm};
use crate::solver::fit::FlowHyperparameters;
use cbd_protocol::{ConfigurationKernel, JointKernel, JointKernelAxis, Normalisation, TaskKernel};

/// CbD's hyperparameters in the data's units (what `--sigma`, `--task-width`, … mean everywhere).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct CbdHyperparameters {
    /// One axis per joint: periodic b (revolute; 1/rad², larger is narrower) or Gaussian width ℓ
    /// (prismatic; the joint's unit).
    pub joint_axes: Vec<JointKernelAxis>,
    /// γ_V: variance of the joint-space displacement field (rad² for revolute joints).
    pub joint_gamma: f64,
    /// a: task-space kernel width, data length unit.
    pub task_width: f64,
    /// γ_W: variance of the task-space displacement field, data length unit squared.
    pub task_gamma: f64,
    /// σ: measurement noise per coordinate, data length unit.
    pub sigma: f64,
    /// The configuration-dependent task term (docs/DESIGN.md §16), when the model has it.
    pub configuration: Option<ConfigurationHyperparameters>,
}

/// The configuration term γ_C K̃_Q(q, q') K̃_X(k0, k0') I in the data's units.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct ConfigurationHyperparameters {
    /// K̃_Q's axes, one per joint, in the joint kernel's forms (periodic c_d, Gaussian width).
    pub joint_axes: Vec<JointKernelAxis>,
    /// a_C, data length unit; `None`: flat (K̃_X = 1, its width at the search's upper bound).
    pub task_width: Option<f64>,
    /// γ_C, data length unit squared.
    pub gamma: f64,
}

impl CbdHyperparameters {
    /// User → internal: γ = γ_V / γ_W (normalised), a / scale, σ / √γ_W. The blob's task kernel has
    /// unit amplitude (scaling both kernels and σ² together leaves the fit unchanged).
    pub fn to_internal(&self, norm: &Normalisation) -> FlowHyperparameters {
        let gamma_w = norm.variance_to_internal(self.task_gamma);
        FlowHyperparameters {
            joint_kernel: JointKernel {
                gamma: self.joint_gamma / gamma_w,
                axes: heapless::Vec::from_slice(&self.joint_axes).expect("at most MAX_JOINTS axes"),
            },
            task_kernel: TaskKernel { width: norm.length_to_internal(self.task_width) },
            // The normalisation cancels in σ / √γ_W: taken in the data's units, as every blob has been.
            sigma: self.sigma / self.task_gamma.sqrt(),
            // γ_C / γ_W like the joint kernel's γ (both in the data's units: the scale cancels).
            configuration_kernel: self.configuration.as_ref().map(|c| ConfigurationKernel {
                gamma: c.gamma / self.task_gamma,
                axes: heapless::Vec::from_slice(&c.joint_axes).expect("at most MAX_JOINTS axes"),
                task_width: c.task_width.map(|a| norm.length_to_internal(a)),
            }),
        }
    }
}

impl Theta {
    /// Internal → user: the evidence's θ (logarithms, normalised units) in the data's units;
    /// `forms[d]`: joint d's axis form (its parameter is not normalised: joint values are not).
    pub(super) fn to_user(&self, forms: &[&dyn AxisForm], norm: &Normalisation) -> CbdHyperparameters {
        let joint_axes = axes_at(forms, &self.log_widths);
        CbdHyperparameters {
            joint_axes,
            joint_gamma: self.log_gamma_v.exp(),
            task_width: norm.length_to_user(self.log_a.exp()),
            task_gamma: norm.variance_to_user(self.log_gamma_w.exp()),
            sigma: norm.length_to_user(self.log_sigma.exp()),
            configuration: self.config.as_ref().map(|c| ConfigurationHyperparameters {
                joint_axes: axes_at(forms, &c.log_widths),
                task_width: Some(norm.length_to_user(c.log_a.exp())),
                gamma: norm.variance_to_user(c.log_gamma.exp()),
            }),
        }
    }

    /// User → θ: the inverse of [`Theta::to_user`] (a flat configuration task factor at `flat_log_a`).
    pub(super) fn from_user(h: &CbdHyperparameters, norm: &Normalisation, flat_log_a: f64) -> Theta {
        let log_params = |axes: &[JointKernelAxis]| axes.iter().map(|a| crate::axis_forms::form_and_parameter(a).1.ln()).collect();
        Theta {
            log_widths: log_params(&h.joint_axes),
            log_gamma_v: h.joint_gamma.ln(),
            log_a: norm.length_to_internal(h.task_width).ln(),
            log_gamma_w: norm.variance_to_internal(h.task_gamma).ln(),
            log_sigma: norm.length_to_internal(h.sigma).ln(),
            config: h.configuration.as_ref().map(|c| super::table::ConfigTheta {
                log_widths: log_params(&c.joint_axes),
                log_a: c.task_width.map_or(flat_log_a, |a| norm.length_to_internal(a).ln()),
                log_gamma: norm.variance_to_internal(c.gamma).ln(),
            }),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// θ → user → internal lands on θ's own normalised values (to rounding), whatever the scale.
    #[test]
    fn the_conversions_meet_in_normalised_units() {
        let norm = Normalisation { task_offset: [3.0, -1.0, 0.5], task_scale: 250.0 };
        let theta = Theta {
            log_widths: vec![0.3f64.ln(), 2.0f64.ln()],
            log_gamma_v: -3.0,
            log_a: 0.2,
            log_gamma_w: -4.0,
            log_sigma: -5.0,
            config: None,
        };
        let user = theta.to_user(&[&crate::axis_forms::Periodic, &crate::axis_forms::Gaussian], &norm);
        assert_eq!(
            user.joint_axes,
            vec![JointKernelAxis::Periodic { b: 0.3f64.ln().exp() }, JointKernelAxis::Gaussian { width: 2.0f64.ln().exp() }]
        );
        let internal = user.to_internal(&norm);
        let close = |a: f64, b: f64| (a - b).abs() <= 1e-14 * b.abs();
        let (gv, gw) = (theta.log_gamma_v.exp(), theta.log_gamma_w.exp());
        assert!(close(internal.joint_kernel.gamma, gv / gw));
        assert!(close(internal.task_kernel.width, theta.log_a.exp()));
        assert!(close(internal.sigma, theta.log_sigma.exp() / gw.sqrt()));
    }
}

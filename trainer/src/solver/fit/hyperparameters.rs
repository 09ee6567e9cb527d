//! The internal form of CbD's hyperparameters: what the fit optimises with and the blob records.

use cbd_protocol::{ConfigurationKernel, JointKernel, TaskKernel};

/// The flow's kernels and noise in internal (normalised) units. The task kernel has unit
/// amplitude: scaling both kernels and σ² together leaves the fit unchanged, so γ_W is folded into
/// the joint kernel's γ and into σ. The user's form, in the data's units, is
/// `evidence::CbdHyperparameters`; `CbdHyperparameters::to_internal` converts.
#[derive(Debug, Clone, PartialEq)]
pub struct FlowHyperparameters {
    /// K_V with γ = γ_V / γ_W (γ_W normalised).
    pub joint_kernel: JointKernel,
    /// K_W: the width a in internal units.
    pub task_kernel: TaskKernel,
    /// σ of energy (16) for these kernels: σ / √γ_W.
    pub sigma: f64,
    /// The configuration-dependent task term (docs/DESIGN.md §16): γ_C / γ_W, K̃_Q's axes, a_C internal.
    pub configuration_kernel: Option<ConfigurationKernel>,
}

//! Format 5: the fields written in their kernels' own finite expansions (docs/DESIGN.md §11).
//!
//! With the very flat kernels the evidence chooses, the momenta of the kernel form cancel to 1 part
//! in 1e5–1e12 and an evaluation in f32 is off by metres. Each kernel has a finite expansion —
//! periodic exp(b(cos Δ − 1)) = Σ_h e^{−b} I_h(b) (2 − δ_h0) cos hΔ per axis, Gaussian
//! exp(−|y − y'|²/2a²) = g(y) g(y') Σ_α u^α u'^α / α! — so each field is a short sum of fixed basis
//! functions with weights the blob stores directly.

use serde::{Deserialize, Serialize};

use crate::f64_slice::F64Slice;

/// The fields in their kernels' own expansions (format 5, docs/DESIGN.md §11).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FieldExpansion<'a> {
    /// Truncation tolerance: the prior weight each kernel's expansion drops, relative to the kernel's total weight.
    pub tolerance: f64,
    /// Task-space radius (internal units, about the normalisation's origin) within which the task expansion meets `tolerance`.
    pub task_radius: f64,
    /// r_V: joint basis functions.
    pub n_joint_features: u32,
    /// r_V × n codes, row-major (one byte per joint axis). Periodic axis: `h << 1 | s`, factor cos(h x) (s = 0) or sin(h x) (s = 1), h ≤ MAX_EXPANSION_ORDER.
    /// Gaussian axis of width ℓ (the JointKernelAxis::Gaussian width): `k << 1` (s must be 0), factor e^{−x²/(2ℓ²)} (x/ℓ)^k / √(k!).
    #[serde(borrow)]
    pub joint_codes: &'a [u8],
    /// r_W: task basis functions.
    pub n_task_features: u32,
    /// r_W × m exponents α_c ≤ MAX_EXPANSION_ORDER, row-major: ψ(y) = e^{−|y|²/(2a²)} Π_c (y_c/a)^{α_c} / √(α_c!), a = task_kernel.width, y internal units.
    #[serde(borrow)]
    pub task_exponents: &'a [u8],
    /// Per integrator stage (stage_count() of them, stage-major): the joint field's weights r_V × n
    /// (v(x) = Σ_f φ_f(x) c_f, c_f ∈ R^n, row f = c_f), then the task field's r_W × m (w(y) = Σ_g ψ_g(y) d_g).
    /// These are the fields of the flow itself (the ODE dk = w(k) − J v(ξ) of DESIGN §2, sign included; joint γ, the momentum law's sign and kernel amplitudes are already folded in).
    #[serde(borrow)]
    pub weights: F64Slice<'a>,
}

impl FieldExpansion<'_> {
    /// Weights of one stage for `n` joints and task dimension `m`: r_V·n + r_W·m.
    pub const fn stage_len(&self, n: usize, m: usize) -> usize {
        self.n_joint_features as usize * n + self.n_task_features as usize * m
    }
}

/// The harmonic or power of a joint code (`code >> 1`).
pub const fn code_order(code: u8) -> u8 {
    code >> 1
}

/// Whether a periodic joint code is the sine (`code & 1 == 1`).
pub const fn code_is_sin(code: u8) -> bool {
    code & 1 == 1
}

//! The types a blob carries.

use heapless::Vec as HVec;
use serde::{Deserialize, Deserializer, Serialize, Serializer};

use crate::effects::Effects;
use crate::expansion::FieldExpansion;
use crate::limits::{MAX_JOINTS, MAX_TASK_DIM};

/// A calibrated model: nominal kinematics, kernels, integrator, control points and momenta.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Model<'a> {
    pub nominal: NominalModel,
    pub normalisation: Normalisation,
    pub joint_kernel: JointKernel,
    pub task_kernel: TaskKernel,
    pub integrator: Integrator,
    pub momentum_law: MomentumLaw,
    /// Noise level σ of energy (16), internal units (kept for provenance; not used to evaluate).
    pub sigma: f64,
    pub n_points: u32,
    /// Measurement configurations, `n_points × n_joints`, row-major, joint units of the nominal model.
    #[serde(borrow)]
    pub points: F64Slice<'a>,
    /// Optimal initial momenta P0, `n_points × task_dim`, row-major, internal units.
    #[serde(borrow)]
    pub momenta: F64Slice<'a>,
    /// The fields in their kernels' own basis (format 5), evaluated instead of the kernel form when
    /// present; the kernel form above stays as the reference. Encoded after the format-4 payload
    /// (see [`crate::encode`]), so it is skipped here.
    #[serde(skip)]
    pub expansion: Option<FieldExpansion<'a>>,
}

impl Model<'_> {
    pub fn n_joints(&self) -> usize {
        self.nominal.n_joints()
    }
    pub fn task_dim(&self) -> usize {
        self.nominal.task_dim()
    }
}

/// The controller's own kinematics k0.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum NominalModel {
    /// Planar serial arm of revolute joints: y = Σ_k l_k (cos, sin)(x_1 + … + x_k), plus effects.
    PlanarChain { lengths: HVec<f64, MAX_JOINTS>, effects: Effects },
    /// Spatial serial chain from a Denavit–Hartenberg table; task space is the tool position.
    DhChain(DhChain),
}

impl NominalModel {
    /// A planar chain without effects.
    pub fn planar(lengths: &[f64]) -> Option<NominalModel> {
        Some(NominalModel::PlanarChain { lengths: HVec::from_slice(lengths).ok()?, effects: Effects::NONE_PLANAR })
    }
    /// The physical effects on top of the rigid chain.
    pub fn effects(&self) -> &Effects {
        match self {
            NominalModel::PlanarChain { effects, .. } => effects,
            NominalModel::DhChain(c) => &c.effects,
        }
    }
    pub fn effects_mut(&mut self) -> &mut Effects {
        match self {
            NominalModel::PlanarChain { effects, .. } => effects,
            NominalModel::DhChain(c) => &mut c.effects,
        }
    }
    pub fn n_joints(&self) -> usize {
        match self {
            NominalModel::PlanarChain { lengths, .. } => lengths.len(),
            NominalModel::DhChain(c) => c.joints.len(),
        }
    }
    pub fn task_dim(&self) -> usize {
        match self {
            NominalModel::PlanarChain { .. } => 2,
            NominalModel::DhChain(_) => 3,
        }
    }
    /// Whether joint `d` is an angle (periodic).
    pub fn is_revolute(&self, d: usize) -> bool {
        match self {
            NominalModel::PlanarChain { .. } => true,
            NominalModel::DhChain(c) => c.joints.get(d).map(|j| j.kind == JointKind::Revolute).unwrap_or(true),
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum DhConvention {
    /// T_i = Rz(θ) Tz(d) Tx(a) Rx(α)
    Standard,
    /// Craig's modified convention: T_i = Rx(α) Tx(a) Rz(θ) Tz(d)
    Modified,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum JointKind {
    Revolute,
    Prismatic,
}

/// One row of a DH table. Lengths in the model's length unit, angles in radians.
/// For a revolute joint θ = q + theta_offset; for a prismatic joint d = q + d.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct DhJoint {
    pub kind: JointKind,
    pub a: f64,
    pub alpha: f64,
    pub d: f64,
    pub theta_offset: f64,
}

/// A rigid transform: rotation (row-major 3×3) and translation.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Transform {
    pub rotation: [f64; 9],
    pub translation: [f64; 3],
}

impl Transform {
    pub const IDENTITY: Transform = Transform { rotation: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0], translation: [0.0; 3] };
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DhChain {
    pub convention: DhConvention,
    pub joints: HVec<DhJoint, MAX_JOINTS>,
    pub base: Transform,
    pub tool: Transform,
    /// Physical effects on top of the rigid chain.
    pub effects: Effects,
}

/// Task-space normalisation: internal = (user − offset) / scale.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Normalisation {
    pub task_offset: [f64; MAX_TASK_DIM],
    pub task_scale: f64,
}

impl Normalisation {
    pub const IDENTITY: Normalisation = Normalisation { task_offset: [0.0; MAX_TASK_DIM], task_scale: 1.0 };
}

/// K_V(x, x') = γ · exp(Σ_d f_d(x_d − x'_d)); f_d = b_d (cos Δ − 1) (periodic) or −Δ²/(2 ℓ_d²).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct JointKernel {
    pub gamma: f64,
    pub axes: HVec<JointKernelAxis, MAX_JOINTS>,
}

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub enum JointKernelAxis {
    /// b (cos Δ − 1): for revolute joints, periodic in 2π.
    Periodic { b: f64 },
    /// −Δ² / (2 ℓ²): for prismatic joints.
    Gaussian { width: f64 },
}

/// K_W(y, y') = exp(−|y − y'|² / (2 a²)), internal units.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct TaskKernel {
    pub width: f64,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum IntegratorMethod {
    /// Forward Euler: one stage per step.
    Euler,
    /// Heun's method (explicit trapezoid): two stages per step.
    Heun,
    /// Classical Runge–Kutta: four stages per step.
    Rk4,
}

impl IntegratorMethod {
    pub const fn stages(self) -> usize {
        match self {
            IntegratorMethod::Euler => 1,
            IntegratorMethod::Heun => 2,
            IntegratorMethod::Rk4 => 4,
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Integrator {
    pub method: IntegratorMethod,
    pub steps: u16,
}

impl Integrator {
    /// Right-hand-side evaluations per integration, i.e. stored trajectory samples.
    pub const fn stage_count(&self) -> usize {
        self.method.stages() * self.steps as usize
    }
}

/// How the momenta drive the joint field and evolve (docs/DESIGN.md §2).
///
/// `WithDivergence` and `WithoutDivergence` (format 2) take v = +Σ_j K_V(x, x_j) J_jᵀ P_j, with or
/// without the −(div v) P term in the momentum law. The `Hamiltonian` laws (format 3) take
/// v = −Σ_j K_V(x, x_j) J_jᵀ P_j, the field that maximises the Hamiltonian Σ Pᵀ(w − J v) − ½|v|² − ½|w|²:
/// then the flow's linearisation at P0 = 0 is k0 + K_lin P0 with the same K_lin = Dk0 K_V Dk0ᵀ + K_W
/// as the regulariser, so energy (16) is exactly the negative log posterior of a Gaussian process
/// with covariance K_lin, whose marginal likelihood chooses the hyperparameters. (With the `+`
/// field the linear response is K_W − Dk0 K_V Dk0ᵀ: joint and task fields partly cancel.)
/// New variants are appended, so format-2 blobs decode unchanged.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum MomentumLaw {
    WithDivergence,
    WithoutDivergence,
    Hamiltonian,
    HamiltonianWithoutDivergence,
}

impl MomentumLaw {
    /// Whether the momentum law has the −(div v) P term.
    pub const fn has_divergence(self) -> bool {
        matches!(self, MomentumLaw::WithDivergence | MomentumLaw::Hamiltonian)
    }
    /// The sign s in v = s Σ_j K_V(x, x_j) J_jᵀ P_j.
    pub const fn joint_field_sign(self) -> f64 {
        match self {
            MomentumLaw::WithDivergence | MomentumLaw::WithoutDivergence => 1.0,
            MomentumLaw::Hamiltonian | MomentumLaw::HamiltonianWithoutDivergence => -1.0,
        }
    }
    /// The oldest blob format that can hold this law.
    pub const fn first_format(self) -> u16 {
        match self {
            MomentumLaw::WithDivergence | MomentumLaw::WithoutDivergence => 2,
            MomentumLaw::Hamiltonian | MomentumLaw::HamiltonianWithoutDivergence => 3,
        }
    }
}

impl JointKernel {
    /// The kernel the flow integrates with for `law`: γ carries the joint field's sign, so every
    /// flow and tangent formula stays one expression (negation is exact: values are ±|γ| e^f, bit
    /// for bit). Only the flow uses it; the regulariser and the blob keep γ > 0.
    pub fn for_flow(&self, law: MomentumLaw) -> JointKernel {
        let mut k = self.clone();
        k.gamma *= law.joint_field_sign();
        k
    }
}

/// A borrowed array of little-endian `f64`, read in place (no alignment needed, no copy).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct F64Slice<'a>(&'a [u8]);

impl<'a> F64Slice<'a> {
    /// Wraps little-endian bytes; the length must be a multiple of 8 (checked on validation).
    pub const fn from_le_bytes(bytes: &'a [u8]) -> Self {
        F64Slice(bytes)
    }
    pub fn len(&self) -> usize {
        self.0.len() / 8
    }
    pub fn is_empty(&self) -> bool {
        self.0.len() < 8
    }
    pub fn byte_len(&self) -> usize {
        self.0.len()
    }
    pub fn bytes(&self) -> &'a [u8] {
        self.0
    }
    /// The `i`-th value, or `None` past the end.
    #[inline]
    pub fn get(&self, i: usize) -> Option<f64> {
        let b = self.0.get(i * 8..i * 8 + 8)?;
        let mut a = [0u8; 8];
        for (d, s) in a.iter_mut().zip(b) {
            *d = *s;
        }
        Some(f64::from_le_bytes(a))
    }
    pub fn iter(&self) -> impl Iterator<Item = f64> + 'a {
        self.0.chunks_exact(8).map(|c| {
            let mut a = [0u8; 8];
            for (d, s) in a.iter_mut().zip(c) {
                *d = *s;
            }
            f64::from_le_bytes(a)
        })
    }
}

impl Serialize for F64Slice<'_> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_bytes(self.0)
    }
}

impl<'de: 'a, 'a> Deserialize<'de> for F64Slice<'a> {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        <&'de [u8]>::deserialize(d).map(F64Slice)
    }
}

/// Little-endian bytes of `values` (std only), for building a [`F64Slice`].
#[cfg(feature = "std")]
pub fn f64_le_bytes(values: &[f64]) -> std::vec::Vec<u8> {
    values.iter().flat_map(|v| v.to_le_bytes()).collect()
}

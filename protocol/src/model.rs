//! The types a blob carries.

use heapless::Vec as HVec;
use serde::{Deserialize, Serialize};

use crate::expansion::FieldExpansion;
use crate::f64_slice::F64Slice;
use crate::limits::{MAX_JOINTS, MAX_TOOL_POINTS};
use crate::normalisation::Normalisation;
use crate::physical_effects::Effects;

/// A calibrated model: nominal kinematics, kernels, integrator, control points and momenta.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Model<'a> {
    /// The controller's nominal kinematics k0 (with its effects), in the model's own units.
    pub nominal: NominalModel,
    /// Task-space normalisation between the model's units and the flow's internal units.
    pub normalisation: Normalisation,
    /// K_V, the joint-space kernel.
    pub joint_kernel: JointKernel,
    /// K_W, the task-space kernel (internal units).
    pub task_kernel: TaskKernel,
    /// The fixed-step scheme the flow is integrated with.
    pub integrator: Integrator,
    /// The sign of the joint field and the momenta's divergence term (docs/DESIGN.md §2).
    pub momentum_law: MomentumLaw,
    /// Noise level σ of energy (16), internal units (kept for provenance; not used to evaluate).
    pub sigma: f64,
    /// The number of control points: N·m_p for N measured poses of m_p tool points
    /// ([`NominalModel::tool_point_count`]); control point c = pose·m_p + j is tool point j = c % m_p.
    pub n_points: u32,
    /// Each control point's configuration, `n_points × n_joints`, row-major, joint units of the
    /// nominal model (pose-major: a pose's configuration is repeated for each of its m_p tool points).
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
    /// The measurement noise σ per coordinate the calibration assumed — its evidence's estimate, or
    /// the value given — in the nominal model's length unit (format 7): what a perfect model's
    /// error on new rows is set against (the noise floor). Not used to evaluate. Encoded after the
    /// format-6 tool points, so it is skipped here.
    #[serde(skip)]
    pub noise_sigma: Option<f64>,
    /// K_C, the configuration-dependent task field's kernel (format 8, docs/DESIGN.md §16): the task
    /// field gains γ_C K_Q(q, q_j) K_X(y, y_j) P_j, a velocity of task space that depends on the
    /// query's configuration q (a flow on Q × X that keeps q fixed). `None`: the paper's two fields.
    /// Encoded after the format-7 σ, so it is skipped here.
    #[serde(skip)]
    pub configuration_kernel: Option<ConfigurationKernel>,
    /// The drift in measurement order the calibration's rows carried (format 8, issue 49 item 2),
    /// beside σ: what a perfect model's error on rows measured at another time is set against (the
    /// noise floor, `cbd check`). Not used to evaluate. Encoded after the configuration kernel.
    #[serde(skip)]
    pub drift: Option<RowDrift>,
    /// Where the blob came from (format 9): the import the rows were read through, the blob this
    /// one updates. Not used to evaluate. Encoded after the drift.
    #[serde(skip)]
    pub provenance: Option<Provenance>,
}

/// What a calibration records about its rows and its parent (format 9); each part is optional and
/// at least one is present (an empty record is not written: [`Model::provenance`] is then `None`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Provenance {
    /// The import the calibration's rows were read through, where it was more than units.
    pub import_frame: Option<ImportFrame>,
    /// SHA-256 of the blob this one updates (`cbd check --update`).
    pub parent: Option<[u8; 32]>,
}

impl Provenance {
    /// No part present.
    pub fn is_empty(&self) -> bool {
        self.import_frame.is_none() && self.parent.is_none()
    }
}

/// Fingerprints (64 bits of a SHA-256 the trainer computes over rounded values in a fixed order) of
/// the import beyond units that turned a file's columns into the chain's joints and frame; `None`
/// where the import is the identity. A blob is used with a model file whose import gives the same
/// fingerprints, or its rows would be read into another frame than it was fitted in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct ImportFrame {
    /// The joints' import as an affine map in model units (`[measurements.joint_map]`'s signs,
    /// scales, coupling and offsets, a `[planar]` arm's joint offsets).
    pub joints: Option<u64>,
    /// The positions' import (a `[planar]` arm's base and yaw).
    pub positions: Option<u64>,
}

/// A stationary process over the rows in measurement order, correlation exp(−lag / length):
/// part of the calibration's residual that followed the time of measurement, not the pose.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct RowDrift {
    /// Standard deviation per coordinate, the nominal model's length unit (≥ 0).
    pub sd: f64,
    /// Correlation length in poses (> 0).
    pub length: f64,
}

impl Model<'_> {
    /// n, the number of joints.
    pub fn n_joints(&self) -> usize {
        self.nominal.n_joints()
    }
    /// m, the task-space dimension (2 planar, 3 spatial).
    pub fn task_dim(&self) -> usize {
        self.nominal.task_dim()
    }
}

/// The controller's own kinematics k0.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
// The variants are stored inline (no heap on the controller): a DH chain is larger than a planar one.
#[allow(clippy::large_enum_variant)]
pub enum NominalModel {
    /// Planar serial arm of revolute joints: y = Σ_k l_k (cos, sin)(x_1 + … + x_k), plus effects.
    PlanarChain {
        /// Link lengths l_k, base first (length units).
        lengths: HVec<f64, MAX_JOINTS>,
        /// Physical effects on top of the rigid chain.
        effects: Effects,
    },
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
    /// The physical effects on top of the rigid chain, to change.
    pub fn effects_mut(&mut self) -> &mut Effects {
        match self {
            NominalModel::PlanarChain { effects, .. } => effects,
            NominalModel::DhChain(c) => &mut c.effects,
        }
    }
    /// n, the number of joints.
    pub fn n_joints(&self) -> usize {
        match self {
            NominalModel::PlanarChain { lengths, .. } => lengths.len(),
            NominalModel::DhChain(c) => c.joints.len(),
        }
    }
    /// m, the task-space dimension: 2 for a planar chain, 3 (the tool position) for a DH chain.
    pub fn task_dim(&self) -> usize {
        match self {
            NominalModel::PlanarChain { .. } => 2,
            NominalModel::DhChain(_) => 3,
        }
    }
    /// m_p, the number of measured points per pose: the DH chain's tool points (1 when it names
    /// none: the tool frame's origin); 1 for a planar chain.
    pub fn tool_point_count(&self) -> usize {
        match self {
            NominalModel::PlanarChain { .. } => 1,
            NominalModel::DhChain(c) => c.tool_points.len().max(1),
        }
    }
    /// Tool point `j`'s offset in the tool frame: the stored offset, or [0, 0, 0] for `j = 0` of a
    /// model without tool points (planar chains: `j = 0` only); `None` beyond [`Self::tool_point_count`].
    pub fn tool_point(&self, j: usize) -> Option<[f64; 3]> {
        match self {
            NominalModel::DhChain(c) if !c.tool_points.is_empty() => c.tool_points.get(j).copied(),
            _ => (j == 0).then_some([0.0; 3]),
        }
    }
    /// The tool points of a DH chain (empty for a planar chain and for a chain without any).
    pub fn tool_points(&self) -> &[[f64; 3]] {
        match self {
            NominalModel::PlanarChain { .. } => &[],
            NominalModel::DhChain(c) => &c.tool_points,
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

/// Which Denavit–Hartenberg convention a table is written in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum DhConvention {
    /// T_i = Rz(θ) Tz(d) Tx(a) Rx(α)
    Standard,
    /// Craig's modified convention: T_i = Rx(α) Tx(a) Rz(θ) Tz(d)
    Modified,
}

/// How a joint moves.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum JointKind {
    /// Rotation about its axis; the joint value is an angle (radians).
    Revolute,
    /// Translation along its axis; the joint value is a length (the model's length unit).
    Prismatic,
}

/// One row of a DH table. Lengths in the model's length unit, angles in radians.
/// For a revolute joint θ = q + theta_offset; for a prismatic joint d = q + d.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct DhJoint {
    /// Revolute or prismatic.
    pub kind: JointKind,
    /// Link length a (along x).
    pub a: f64,
    /// Link twist α (about x, radians).
    pub alpha: f64,
    /// Link offset d (along z); for a prismatic joint, its value at q = 0.
    pub d: f64,
    /// θ at q = 0 (radians); for a prismatic joint, the fixed θ.
    pub theta_offset: f64,
}

/// A rigid transform: rotation (row-major 3×3) and translation.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Transform {
    /// R, row-major: `rotation[3 * row + col]`.
    pub rotation: [f64; 9],
    /// t, in the model's length unit.
    pub translation: [f64; 3],
}

impl Transform {
    /// R = I, t = 0.
    pub const IDENTITY: Transform = Transform { rotation: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0], translation: [0.0; 3] };
}

/// A serial chain from a DH table: base ∘ T_1(q_1) ∘ … ∘ T_n(q_n) ∘ tool; task space is the tool point.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DhChain {
    /// The table's convention.
    pub convention: DhConvention,
    /// One row per joint, base first.
    pub joints: HVec<DhJoint, MAX_JOINTS>,
    /// The first DH frame in the task (world) frame.
    pub base: Transform,
    /// The tool frame in the last DH frame; its origin is the tool point.
    pub tool: Transform,
    /// Physical effects on top of the rigid chain.
    pub effects: Effects,
    /// The measured points' offsets in the tool frame (the `tool` transform's frame, the model's
    /// length unit), at most [`MAX_TOOL_POINTS`] (format 6). Empty: one point at the tool frame's
    /// origin, the meaning of every blob before format 6. Encoded after the format-5 payload (see
    /// [`crate::encode`]), so it is skipped here.
    #[serde(skip)]
    pub tool_points: HVec<[f64; 3], MAX_TOOL_POINTS>,
}

/// K_V(x, x') = γ · exp(Σ_d f_d(x_d − x'_d)); f_d = b_d (cos Δ − 1) (periodic) or −Δ²/(2 ℓ_d²).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct JointKernel {
    /// γ, the amplitude (> 0 in a blob; the flow's copy carries the momentum law's sign).
    pub gamma: f64,
    /// f_d, one per joint.
    pub axes: HVec<JointKernelAxis, MAX_JOINTS>,
}

/// One joint's factor of K_V.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub enum JointKernelAxis {
    /// b (cos Δ − 1): for revolute joints, periodic in 2π.
    Periodic {
        /// b > 0 (dimensionless): larger is narrower.
        b: f64,
    },
    /// −Δ² / (2 ℓ²): for prismatic joints.
    Gaussian {
        /// ℓ > 0, in the joint's length unit.
        width: f64,
    },
}

/// K_W(y, y') = exp(−|y − y'|² / (2 a²)), internal units.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct TaskKernel {
    /// a > 0, internal units.
    pub width: f64,
}

/// K_C((q, y), (q', y')) = γ_C exp(Σ_d f_d(q_d − q'_d)) · exp(−|y − y'|² / (2 a_C²)): the kernel of
/// the task field whose velocity depends on the configuration (format 8). Its joint factor has its
/// own axes (f_d as [`JointKernelAxis`]), its task factor its own width, or none (`task_width`
/// `None`: constant in y, the field a translation of task space that depends on q).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ConfigurationKernel {
    /// γ_C > 0, relative to K_W's unit amplitude (normalised as the joint kernel's γ).
    pub gamma: f64,
    /// f_d, one per joint (periodic on revolute joints, Gaussian on prismatic ones).
    pub axes: HVec<JointKernelAxis, MAX_JOINTS>,
    /// a_C > 0, internal units; `None`: the factor is 1 (flat in task space).
    pub task_width: Option<f64>,
}

/// The explicit Runge–Kutta method of the fixed-step integration.
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
    /// Right-hand-side evaluations per step.
    pub const fn stages(self) -> usize {
        match self {
            IntegratorMethod::Euler => 1,
            IntegratorMethod::Heun => 2,
            IntegratorMethod::Rk4 => 4,
        }
    }
}

/// Fixed-step integration of the flow over t ∈ [0, 1].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Integrator {
    /// The method of each step.
    pub method: IntegratorMethod,
    /// Equal steps over [0, 1] (1..=[`crate::MAX_STEPS`]).
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
    /// s = +1, with the −(div v) P term (format 2).
    WithDivergence,
    /// s = +1, without the divergence term (format 2).
    WithoutDivergence,
    /// s = −1, with the divergence term (format 3; the default).
    Hamiltonian,
    /// s = −1, without the divergence term (format 3).
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

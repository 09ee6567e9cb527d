//! k0 and Dk0 of the rigid chain alone (planar chain or DH table, effects aside): the one DH frame
//! walk. `kinematics::forward_kinematics` dispatches here for effect-free models, and the effects
//! build on it.

use crate::kinematics::spatial::{cross, sub, Frame};
use cbd_protocol::{DhChain, DhConvention, DhJoint, JointKind, NominalModel, Normalisation, MAX_JOINTS, MAX_TASK_DIM};

/// Position (first `task_dim` entries) and Jacobian (row-major, `task_dim × n_joints`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Kinematics {
    /// k0(x), model units (internal units after [`Kinematics::normalised`]).
    pub position: [f64; MAX_TASK_DIM],
    /// Dk0(x), `jacobian[a][d] = ∂k0_a/∂x_d`.
    pub jacobian: [[f64; MAX_JOINTS]; MAX_TASK_DIM],
}

impl Kinematics {
    const ZERO: Kinematics = Kinematics { position: [0.0; MAX_TASK_DIM], jacobian: [[0.0; MAX_JOINTS]; MAX_TASK_DIM] };

    /// Maps user units to internal ones: (y − offset) · (1/scale), J · (1/scale) (the reciprocal:
    /// blobs record these bits, `Normalisation::position_to_internal_by_reciprocal`).
    pub fn normalised(mut self, norm: &Normalisation) -> Kinematics {
        for (axis, (p, row)) in self.position.iter_mut().zip(self.jacobian.iter_mut()).enumerate() {
            *p = norm.position_to_internal_by_reciprocal(axis, *p);
            for j in row.iter_mut() {
                *j = norm.length_to_internal_by_reciprocal(*j);
            }
        }
        self
    }
}

/// k0(x) and Dk0(x) of the chain, ignoring any effects the model carries.
#[inline]
pub fn kinematics(model: &NominalModel, x: &[f64]) -> Kinematics {
    match model {
        NominalModel::PlanarChain { lengths, .. } => planar_chain(lengths, x),
        NominalModel::DhChain(chain) => dh_chain(chain, x),
    }
}

// y = Σ_k l_k (cos θ_k, sin θ_k), θ_k = x_1 + … + x_k.
fn planar_chain(lengths: &[f64], x: &[f64]) -> Kinematics {
    let mut out = Kinematics::ZERO;
    let mut theta = 0.0;
    let [jac_x, jac_y, _] = &mut out.jacobian;
    for (k, (l, xk)) in lengths.iter().zip(x).enumerate() {
        theta += xk;
        let (s, c) = (libm::sin(theta), libm::cos(theta));
        out.position[0] += l * c;
        out.position[1] += l * s;
        // Link k moves with every joint d ≤ k.
        for (jx, jy) in jac_x.iter_mut().zip(jac_y.iter_mut()).take(k + 1) {
            *jx -= l * s;
            *jy += l * c;
        }
    }
    out
}

fn rot_z_trans_z(theta: f64, d: f64) -> Frame {
    let (s, c) = (libm::sin(theta), libm::cos(theta));
    Frame([[c, -s, 0.0, 0.0], [s, c, 0.0, 0.0], [0.0, 0.0, 1.0, d]])
}

fn trans_x_rot_x(a: f64, alpha: f64) -> Frame {
    let (s, c) = (libm::sin(alpha), libm::cos(alpha));
    Frame([[1.0, 0.0, 0.0, a], [0.0, c, -s, 0.0], [0.0, s, c, 0.0]])
}

/// θ and d of `joint` at joint value `x`: θ = x + θ_offset (revolute) or d = x + d (prismatic).
#[inline(always)]
pub fn dh_variables(joint: &DhJoint, x: f64) -> (f64, f64) {
    match joint.kind {
        JointKind::Revolute => (x + joint.theta_offset, joint.d),
        JointKind::Prismatic => (joint.theta_offset, x + joint.d),
    }
}

/// One DH row's transform at θ and d, the product of the two factors [`dh_walk`] multiplies
/// one after the other: Rz(θ) Tz(d) · Tx(a) Rx(α) (standard) or Tx(a) Rx(α) · Rz(θ) Tz(d) (modified).
pub fn dh_transform(convention: DhConvention, theta: f64, d: f64, a: f64, alpha: f64) -> Frame {
    match convention {
        DhConvention::Standard => rot_z_trans_z(theta, d).compose(&trans_x_rot_x(a, alpha)),
        DhConvention::Modified => trans_x_rot_x(a, alpha).compose(&rot_z_trans_z(theta, d)),
    }
}

/// Per joint of a DH chain at joints `x`, in the base frame: its axis z_i, a point o_i on it, and
/// `ends[i]`, the origin of the frame after the joint's full transform (the distal end of link i).
#[derive(Debug, Clone, Copy)]
pub struct DhWalk {
    /// z_i, the unit axis of joint i.
    pub axes: [[f64; 3]; MAX_JOINTS],
    /// o_i, a point on axis i (the origin of the frame joint i moves about or along).
    pub origins: [[f64; 3]; MAX_JOINTS],
    /// The distal end of link i: the origin of the frame after joint i's full transform.
    pub ends: [[f64; 3]; MAX_JOINTS],
    /// Rotation (row-major rows) of the frame whose origin is `ends[i]`: link i's own frame.
    pub end_rotations: [[[f64; 3]; 3]; MAX_JOINTS],
    /// The base origin (start of link 0).
    pub start: [f64; 3],
    /// Rotation (row-major rows) of the base frame, whose origin is `start`.
    pub start_rotation: [[f64; 3]; 3],
    /// The tool point.
    pub tool: [f64; 3],
    /// Rotation (row-major rows) of the tool frame, whose origin is `tool`.
    pub tool_rotation: [[f64; 3]; 3],
}

/// The one DH frame walk: forward kinematics, its Hessian, the effects, and in the trainer the
/// six-joint simulator, the injected effects, DH calibration's Jacobian and the URDF check all use
/// it. Callers that do not read `ends` or the rotations pay nothing for them (dead stores to a local
/// are removed).
#[inline(always)]
pub fn dh_walk(chain: &DhChain, x: &[f64]) -> DhWalk {
    let mut frame = Frame::from_transform(&chain.base);
    let mut out = DhWalk {
        axes: [[0.0; 3]; MAX_JOINTS],
        origins: [[0.0; 3]; MAX_JOINTS],
        ends: [[0.0; 3]; MAX_JOINTS],
        end_rotations: [[[0.0; 3]; 3]; MAX_JOINTS],
        start: frame.translation(),
        start_rotation: frame.rotation(),
        tool: [0.0; 3],
        tool_rotation: [[0.0; 3]; 3],
    };
    let slots = out.axes.iter_mut().zip(out.origins.iter_mut()).zip(out.ends.iter_mut().zip(out.end_rotations.iter_mut()));
    for ((joint, x_i), ((axis, origin), (end, rotation))) in chain.joints.iter().zip(x).zip(slots) {
        let (theta, d) = dh_variables(joint, *x_i);
        match chain.convention {
            // T_i = Rz(θ) Tz(d) Tx(a) Rx(α): joint i moves about z of frame i−1.
            DhConvention::Standard => {
                *axis = z_axis(&frame);
                *origin = frame.translation();
                frame = frame.compose(&rot_z_trans_z(theta, d));
                frame = frame.compose(&trans_x_rot_x(joint.a, joint.alpha));
            }
            // T_i = Rx(α) Tx(a) Rz(θ) Tz(d): joint i moves about z of frame i.
            DhConvention::Modified => {
                frame = frame.compose(&trans_x_rot_x(joint.a, joint.alpha));
                *axis = z_axis(&frame);
                *origin = frame.translation();
                frame = frame.compose(&rot_z_trans_z(theta, d));
            }
        }
        *end = frame.translation();
        *rotation = frame.rotation();
    }
    frame = frame.compose(&Frame::from_transform(&chain.tool));
    out.tool = frame.translation();
    out.tool_rotation = frame.rotation();
    out
}

/// The frame's z axis (column 2 of its rotation).
fn z_axis(frame: &Frame) -> [f64; 3] {
    let [[_, _, z0, _], [_, _, z1, _], [_, _, z2, _]] = frame.0;
    [z0, z1, z2]
}

/// Joint axes z_i, points o_i on them and the tool point p, in the base frame, at joints `x`.
pub fn dh_frames(chain: &DhChain, x: &[f64]) -> ([[f64; 3]; MAX_JOINTS], [[f64; 3]; MAX_JOINTS], [f64; 3]) {
    let walk = dh_walk(chain, x);
    (walk.axes, walk.origins, walk.tool)
}

fn dh_chain(chain: &DhChain, x: &[f64]) -> Kinematics {
    let (axes, origins, p) = dh_frames(chain, x);
    let mut out = Kinematics::ZERO;
    out.position = p;
    let n = chain.joints.len().min(x.len());
    for (i, ((z, o), joint)) in axes.iter().zip(origins.iter()).zip(chain.joints.iter()).take(n).enumerate() {
        let col = match joint.kind {
            JointKind::Revolute => cross(*z, sub(p, *o)),
            JointKind::Prismatic => *z,
        };
        for (row, v) in out.jacobian.iter_mut().zip(col) {
            if let Some(slot) = row.get_mut(i) {
                *slot = v;
            }
        }
    }
    out
}

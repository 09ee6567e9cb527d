//! A planar arm is a DH chain with α = d = 0 and a planar base (translation in x, y, rotation
//! about z). The protocol's `PlanarChain` holds link lengths only, so calibration of a planar arm
//! (base translation and rotation, joint offsets, link lengths) works on the equivalent DH chain
//! and reads its first two task coordinates: the planar task space of the data.

use super::dh_parameters::parameter_names;
use cbd_protocol::{DhChain, DhConvention, DhJoint, JointKind, NominalModel, Transform};

/// The DH form of `model`: a `PlanarChain` becomes the standard DH chain with a_k = l_k,
/// α = d = θ_offset = 0, identity base and tool, the same effects and the in-plane part of its
/// gravity direction (what the planar runtime uses). A DH chain is returned as it is.
pub fn as_dh(model: &NominalModel) -> NominalModel {
    match model {
        NominalModel::DhChain(_) => model.clone(),
        NominalModel::PlanarChain { lengths, effects } => {
            let joints = lengths.iter().map(|&a| DhJoint { kind: JointKind::Revolute, a, alpha: 0.0, d: 0.0, theta_offset: 0.0 }).collect();
            let mut effects = effects.clone();
            effects.gravity.direction[2] = 0.0;
            NominalModel::DhChain(DhChain {
                convention: DhConvention::Standard,
                joints,
                base: Transform::IDENTITY,
                tool: Transform::IDENTITY,
                effects,
                tool_points: heapless::Vec::new(),
            })
        }
    }
}

/// Indices (into `dh_parameters::parameter_names(n)`) of the parameters that move a planar DH
/// chain's tool within its plane: a_k, θ_offset_k, base x, y translation and base rotation about
/// z. The others (α, d, base z, tilts, tool) move it out of the plane or not at all.
pub fn in_plane_parameters(n: usize) -> Vec<usize> {
    parameter_names(n)
        .iter()
        .enumerate()
        .filter(|(_, name)| {
            (name.starts_with('a') && !name.starts_with("alpha"))
                || name.starts_with("theta_offset")
                || matches!(name.as_str(), "base_tx" | "base_ty" | "base_rz")
        })
        .map(|(k, _)| k)
        .collect()
}

/// A planar arm's DH form seen as a `PlanarChain` in a moved frame: the chain turns at
/// q' = q + offsets, and its positions p map to the arm's as y = R(yaw) p + base.
#[derive(Debug, Clone, PartialEq)]
pub struct PlanarFrame {
    pub offsets: Vec<f64>,
    pub base: [f64; 2],
    pub yaw: f64,
}

impl PlanarFrame {
    /// Joint rows (row-major) in the chain's variables q + offsets.
    pub fn chain_joints(&self, joints: &[f64]) -> Vec<f64> {
        let n = self.offsets.len();
        joints.chunks_exact(n).flat_map(|q| q.iter().zip(&self.offsets).map(|(a, o)| a + o).collect::<Vec<_>>()).collect()
    }
    /// An arm position (x, y) in the chain's frame: R(−yaw) (y − base).
    pub fn to_chain(&self, y: &[f64]) -> [f64; 2] {
        let (s, c) = self.yaw.sin_cos();
        let (dx, dy) = (y[0] - self.base[0], y[1] - self.base[1]);
        [c * dx + s * dy, -s * dx + c * dy]
    }
    /// A chain position in the arm's frame: R(yaw) p + base.
    pub fn from_chain(&self, p: &[f64]) -> [f64; 2] {
        let (s, c) = self.yaw.sin_cos();
        [c * p[0] - s * p[1] + self.base[0], s * p[0] + c * p[1] + self.base[1]]
    }
    /// One measured row into the chain's frame in place: joints `q` (n, or none: a file of
    /// targets) + offsets, position `y` (2, or none: a file of seeds) by [`Self::to_chain`].
    /// Zero offsets and an identity placement leave the values' bits unchanged.
    pub fn move_row(&self, q: &mut [f64], y: &mut [f64]) {
        for (q, o) in q.iter_mut().zip(&self.offsets).filter(|(_, o)| **o != 0.0) {
            *q += o;
        }
        if y.len() == 2 && (self.yaw != 0.0 || self.base != [0.0; 2]) {
            let p = self.to_chain(y);
            y.copy_from_slice(&p);
        }
    }
    /// A frame `inner` given in this frame's chain coordinates, as one frame of the arm:
    /// y = R(yaw) (R(yaw') p + base') + base, the chain turning at q + offsets + offsets'.
    pub fn then(&self, inner: &PlanarFrame) -> PlanarFrame {
        let b = self.from_chain(&inner.base);
        PlanarFrame { offsets: self.offsets.iter().zip(&inner.offsets).map(|(a, b)| a + b).collect(), base: b, yaw: self.yaw + inner.yaw }
    }
}

/// A planar DH form (`as_dh` plus in-plane changes: base x, y, yaw, joint offsets, lengths) as a
/// `PlanarChain` and the frame it sits in, for code that needs the blob's planar chain (the CbD
/// pipeline). The effects move with it: gravity turned into the chain's frame, transmission
/// phases shifted by h·offset. One approximation: an encoder scale s on a joint with offset o
/// also shifts that joint by the constant −s·o, which the chain cannot hold (what CbD on top
/// absorbs). `None` when `model` is not a planar DH form.
pub fn as_planar_in_frame(model: &NominalModel) -> Option<(NominalModel, PlanarFrame)> {
    let NominalModel::DhChain(c) = model else { return None };
    let r = &c.base.rotation;
    let flat = |v: f64| v.abs() < 1e-12;
    let planar = c.convention == DhConvention::Standard
        && c.tool == Transform::IDENTITY
        && flat(c.base.translation[2])
        && flat(r[2])
        && flat(r[5])
        && flat(r[6])
        && flat(r[7])
        && (r[8] - 1.0).abs() < 1e-12
        && c.joints.iter().all(|j| j.kind == JointKind::Revolute && j.alpha == 0.0 && j.d == 0.0);
    if !planar {
        return None;
    }
    let frame = PlanarFrame {
        offsets: c.joints.iter().map(|j| j.theta_offset).collect(),
        base: [c.base.translation[0], c.base.translation[1]],
        yaw: r[3].atan2(r[0]),
    };
    let lengths: Vec<f64> = c.joints.iter().map(|j| j.a).collect();
    let mut chain = NominalModel::planar(&lengths)?;
    let mut effects = c.effects.clone();
    let (s, co) = frame.yaw.sin_cos();
    let g = effects.gravity.direction;
    effects.gravity.direction = [co * g[0] + s * g[1], -s * g[0] + co * g[1], 0.0];
    for e in effects.list.iter_mut() {
        let mut shifted = crate::effects::Instance::of(e);
        let kind = shifted.kind;
        kind.shift_joints(&mut shifted, &frame.offsets);
        *e = shifted.to_blob().expect("a blob effect's kind has a blob form");
    }
    *chain.effects_mut() = effects;
    Some((chain, frame))
}

/// The `PlanarChain` a DH form stands for when it is one exactly (identity base and tool,
/// α = d = θ_offset = 0, revolute joints); `None` when a base or joint-offset correction (which
/// a `PlanarChain` cannot hold) is present.
pub fn as_planar(model: &NominalModel) -> Option<NominalModel> {
    let NominalModel::DhChain(c) = model else { return Some(model.clone()) };
    let plain = c.convention == DhConvention::Standard
        && c.base == Transform::IDENTITY
        && c.tool == Transform::IDENTITY
        && c.joints.iter().all(|j| j.kind == JointKind::Revolute && j.alpha == 0.0 && j.d == 0.0 && j.theta_offset == 0.0);
    if !plain {
        return None;
    }
    let lengths: Vec<f64> = c.joints.iter().map(|j| j.a).collect();
    let mut out = NominalModel::planar(&lengths)?;
    *out.effects_mut() = c.effects.clone();
    Some(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use cbd_protocol::Effect;
    use cbd_runtime::internals::kinematics::forward_kinematics;

    #[test]
    fn the_dh_form_of_a_planar_arm_moves_and_deflects_like_it() {
        let mut planar = NominalModel::planar(&[1.0, 0.5, 0.3]).unwrap();
        planar.effects_mut().gravity.link_masses = heapless::Vec::from_slice(&[1.0, 0.7, 0.4]).unwrap();
        for e in [
            Effect::GravityCompliance { joint: 1, compliance: 0.01 },
            Effect::LinkBending { link: 2, compliance: 0.02 },
            Effect::Transmission { joint: 0, harmonic: 2, cos: 0.003, sin: -0.001 },
            Effect::EncoderScale { joint: 2, scale: 0.002 },
        ] {
            planar.effects_mut().list.push(e).unwrap();
        }
        let dh = as_dh(&planar);
        assert_eq!(dh.task_dim(), 3);
        for q in [[0.3, 1.2, -0.4], [-2.0, 0.4, 2.9], [2.5, -1.1, 0.0]] {
            let (a, b) = (forward_kinematics(&planar, &q).position, forward_kinematics(&dh, &q).position);
            for c in 0..2 {
                assert!((a[c] - b[c]).abs() < 1e-12, "{q:?}: {a:?} vs {b:?}");
            }
            assert!(b[2].abs() < 1e-12);
        }
        assert_eq!(as_planar(&dh), Some(planar.clone()));
        // The same arm moved and with joint offsets is that chain in a moved frame.
        let mut moved = dh.clone();
        if let NominalModel::DhChain(c) = &mut moved {
            c.base = crate::nominal::rotation_about([0.0, 0.0, 1.0], 0.02).with_translation([0.04, -0.03, 0.0]).to_transform();
            c.joints[1].theta_offset = 0.015;
            c.joints[2].theta_offset = -0.01;
        }
        // Without the encoder scale (the one approximation) the two agree to rounding.
        for m in [&mut moved] {
            m.effects_mut().list.retain(|e| !matches!(e, Effect::EncoderScale { .. }));
        }
        let (chain, frame) = as_planar_in_frame(&moved).unwrap();
        for q in [[0.3, 1.2, -0.4], [-2.0, 0.4, 2.9]] {
            let want = forward_kinematics(&moved, &q).position;
            let got = frame.from_chain(&forward_kinematics(&chain, &frame.chain_joints(&q)).position);
            for c in 0..2 {
                assert!((want[c] - got[c]).abs() < 1e-12, "{q:?}: {want:?} vs {got:?}");
            }
        }
        // Five in-plane parameters of 3 joints: 3 lengths, 3 offsets, base x, y and yaw.
        let names: Vec<String> = in_plane_parameters(3).iter().map(|&k| parameter_names(3)[k].clone()).collect();
        assert_eq!(names, ["a1", "theta_offset1", "a2", "theta_offset2", "a3", "theta_offset3", "base_tx", "base_ty", "base_rz"]);
    }
}

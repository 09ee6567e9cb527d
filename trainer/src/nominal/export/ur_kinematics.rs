//! The UR description's kinematics file (ur_description's `kinematics_parameters_file`, what UR's
//! own calibration extraction writes): under `kinematics:`, the origins of the six joints —
//! `shoulder`, `upper_arm`, `forearm`, `wrist_1`, `wrist_2`, `wrist_3` — as x, y, z (metres) and
//! roll, pitch, yaw (radians, URDF's R = Rz(yaw) Ry(pitch) Rx(roll)), and a `hash`.
//!
//! ur_description's `ur_macro.xacro` composes them as base_link → base_link_inertia (rpy 0 0 π,
//! the controller's base frame) → each joint's origin, then its turn about z → wrist_3_link →
//! flange (rpy 0 −π/2 −π/2) → tool0 (rpy π/2 0 π/2). The file's first origin is in the model's
//! base frame, so that frame must be the controller's base (base_link_inertia). What comes after
//! wrist_3 is fixed there: the calibrated tool is the TCP in tool0 ([`UrKinematics::tcp`]).

use super::{decimal, rpy_of, LinkFrames};
use crate::error::{Error, Result};
use crate::nominal::{rpy, Frame};
use cbd_protocol::JointKind;
use std::f64::consts::{FRAC_PI_2, PI};
use std::fmt::Write as _;

/// The file's segments, one per joint, in chain order.
pub const SEGMENTS: [&str; 6] = ["shoulder", "upper_arm", "forearm", "wrist_1", "wrist_2", "wrist_3"];

/// base_link → base_link_inertia in ur_description (base_link is REP-103 aligned; the
/// controller's base, where the first origin hangs, is turned by π about z).
pub fn base_link_to_controller_base() -> Frame {
    rpy(0.0, 0.0, PI)
}

/// wrist_3_link → flange → tool0 in ur_description.
pub fn wrist_3_to_tool0() -> Frame {
    rpy(0.0, -FRAC_PI_2, -FRAC_PI_2).compose(&rpy(FRAC_PI_2, 0.0, FRAC_PI_2))
}

/// A written kinematics file.
#[derive(Debug, Clone, PartialEq)]
pub struct UrKinematics {
    pub text: String,
    /// The six origins (metres).
    pub segments: [Frame; 6],
    /// The calibrated tool in tool0 (metres): the TCP to set on the controller or in MoveIt.
    pub tcp: Frame,
    pub hash: String,
}

/// The kinematics file of `frames` (a six-joint arm turning about each link's z), its first origin
/// relative to `root` (model length unit; `to_metres` per unit). `comment` heads the file.
pub fn ur_kinematics(frames: &LinkFrames, root: &Frame, to_metres: f64, comment: &[String]) -> Result<UrKinematics> {
    if frames.links.len() != 6 || frames.kinds.iter().any(|k| *k != JointKind::Revolute) {
        return Err(Error::InvalidInput(format!(
            "a UR kinematics file describes six revolute joints; this chain has {} joints{}",
            frames.links.len(),
            if frames.kinds.contains(&JointKind::Prismatic) { ", some prismatic" } else { "" }
        )));
    }
    if let Some(i) = frames.axes.iter().position(|a| (a[0].abs() + a[1].abs() + (a[2] - 1.0).abs()) > 1e-12) {
        return Err(Error::InvalidInput(format!(
            "joint {} turns about {:?} in its link's frame; ur_description turns every joint about z (axis 0 0 1)",
            i + 1,
            frames.axes[i]
        )));
    }
    let metres = |f: Frame| f.with_translation(f.translation().map(|v| v * to_metres));
    let segments: [Frame; 6] = std::array::from_fn(|i| metres(frames.origin(i, root)));
    let tcp = wrist_3_to_tool0().inverse().compose(&metres(frames.tip_in_last_link()));
    let mut body = String::new();
    for (name, origin) in SEGMENTS.iter().zip(&segments) {
        let [x, y, z] = origin.translation();
        let [roll, pitch, yaw] = rpy_of(&origin.rotation());
        let _ = writeln!(body, "  {name}:");
        for (key, v) in [("x", x), ("y", y), ("z", z), ("roll", roll), ("pitch", pitch), ("yaw", yaw)] {
            let _ = writeln!(body, "    {key}: {}", decimal(v));
        }
    }
    // The driver compares this with the robot's own calibration hash (a mismatch is a warning):
    // ours names what is written, so two exports of the same kinematics agree.
    let hash = format!("cbd_{:08x}", crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC).checksum(body.as_bytes()));
    let mut text = String::new();
    for line in comment {
        let _ = writeln!(text, "{}", super::yaml_comment(line));
    }
    let _ = writeln!(text, "kinematics:\n{body}  hash: {hash}");
    Ok(UrKinematics { text, segments, tcp, hash })
}

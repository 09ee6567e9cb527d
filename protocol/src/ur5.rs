//! The UR5's nominal kinematics: the manufacturer's standard DH table in millimetres, with the
//! 31 mm tool offset along the flange z axis. The trainer's six-joint simulator and the firmware
//! check's six-joint blob both build on it, so the table is typed once.

use crate::limits::MAX_JOINTS;
use crate::model::{DhChain, DhConvention, DhJoint, JointKind, Transform};
use crate::physical_effects::Effects;
use core::f64::consts::FRAC_PI_2;

/// One revolute row (a and d in mm, α in radians, no θ offset).
const fn revolute(a: f64, alpha: f64, d: f64) -> DhJoint {
    DhJoint { kind: JointKind::Revolute, a, alpha, d, theta_offset: 0.0 }
}

/// The six rows, base first. ±90° is written `FRAC_PI_2`, which has the bits of `90 · π/180`.
pub const DH_TABLE: [DhJoint; 6] = [
    revolute(0.0, FRAC_PI_2, 89.159),
    revolute(-425.0, 0.0, 0.0),
    revolute(-392.25, 0.0, 0.0),
    revolute(0.0, FRAC_PI_2, 109.15),
    revolute(0.0, -FRAC_PI_2, 94.65),
    revolute(0.0, 0.0, 82.3),
];

// Every build holds the six rows (MAX_JOINTS ≥ 7).
const _: () = assert!(DH_TABLE.len() <= MAX_JOINTS);

/// The tool point's offset along the flange z axis (mm).
pub const TOOL_Z: f64 = 31.0;

/// The UR5 as a standard DH chain (mm): [`DH_TABLE`], identity base, tool [`TOOL_Z`] along z, no effects.
pub fn chain() -> DhChain {
    let mut tool = Transform::IDENTITY;
    tool.translation = [0.0, 0.0, TOOL_Z];
    let mut joints = heapless::Vec::new();
    for joint in DH_TABLE {
        // Six rows always fit (checked at compile time above).
        let _ = joints.push(joint);
    }
    DhChain {
        convention: DhConvention::Standard,
        joints,
        base: Transform::IDENTITY,
        tool,
        effects: Effects::NONE,
        tool_points: heapless::Vec::new(),
    }
}

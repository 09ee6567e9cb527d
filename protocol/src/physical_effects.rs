//! Physical effects added to a nominal chain (what `cbd diagnose` finds and `--write-model` keeps).
//!
//! The augmented kinematics is k0(q + δ(q)) + b(q): joint-space deflections δ (encoder scale,
//! transmission harmonics, compliance under gravity) and task-space link bending b. Geometric
//! errors (joint offsets, DH lengths and angles, base and tool) need no entry here: they are
//! written into the DH table itself.

use heapless::Vec as HVec;
use serde::{Deserialize, Serialize};

use crate::limits::MAX_JOINTS;

/// Most effects one model may carry.
pub const MAX_EFFECTS: usize = 48;
/// Highest harmonic a transmission effect may have.
pub const MAX_HARMONIC: u8 = 16;
/// How far from 1 the length of the gravity direction may be.
pub const GRAVITY_UNIT_TOLERANCE: f64 = 1e-9;

/// The effects of a nominal chain and the gravity/mass model the gravity-driven ones use.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
pub struct Effects {
    /// Gravity direction and link masses (used by the gravity-driven effects).
    pub gravity: GravityModel,
    /// The effects, applied together (their deflections add).
    pub list: HVec<Effect, MAX_EFFECTS>,
}

impl Effects {
    /// No effect: the chain alone (spatial default gravity).
    pub const NONE: Effects = Effects { gravity: GravityModel::DEFAULT, list: HVec::new() };
    /// No effect, planar default gravity (−y).
    pub const NONE_PLANAR: Effects = Effects { gravity: GravityModel::PLANAR, list: HVec::new() };

    /// Whether there is no effect (the gravity model alone changes nothing).
    pub fn is_empty(&self) -> bool {
        self.list.is_empty()
    }
}

/// Gravity direction (unit vector, base frame) and point masses at the distal end of each link.
/// Empty `link_masses` means the documented default: one unit mass at the end of every link.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GravityModel {
    /// Unit vector along gravity in the base frame. For a planar chain only the first two
    /// entries are used.
    pub direction: [f64; 3],
    /// Point mass at the distal end of each link (mass units of the model file; empty: unit masses).
    pub link_masses: HVec<f64, MAX_JOINTS>,
}

impl GravityModel {
    /// Gravity along −z of the base frame (a floor-mounted spatial arm).
    pub const DEFAULT: GravityModel = GravityModel { direction: [0.0, 0.0, -1.0], link_masses: HVec::new() };
    /// Gravity along −y: a planar arm moving in a vertical plane.
    pub const PLANAR: GravityModel = GravityModel { direction: [0.0, -1.0, 0.0], link_masses: HVec::new() };
}

impl Default for GravityModel {
    fn default() -> Self {
        GravityModel::DEFAULT
    }
}

/// One physical effect, with its parameter(s). `joint`/`link` are 0-based indices.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub enum Effect {
    /// δ_j = scale · q_j (encoder or gear-ratio scale error).
    EncoderScale {
        /// The joint (0-based).
        joint: u8,
        /// Relative scale error (dimensionless).
        scale: f64,
    },
    /// δ_j = cos · cos(h q_j) + sin · sin(h q_j) (transmission error, harmonic h ≥ 1).
    Transmission {
        /// The joint (0-based).
        joint: u8,
        /// h, cycles per joint revolution (1..=[`MAX_HARMONIC`]).
        harmonic: u8,
        /// Amplitude of the cosine term (joint units).
        cos: f64,
        /// Amplitude of the sine term (joint units).
        sin: f64,
    },
    /// δ_j = compliance · τ_j(q): τ_j the gravity torque at joint j from the mass model.
    GravityCompliance {
        /// The joint (0-based).
        joint: u8,
        /// Deflection per unit gravity torque (joint unit per mass·length unit).
        compliance: f64,
    },
    /// Tool point displaced by compliance · (g − (g·u) u), u the unit direction of link `link`.
    LinkBending {
        /// The link (0-based; link k ends after joint k).
        link: u8,
        /// Displacement per unit of the gravity component across the link (length units).
        compliance: f64,
    },
    /// One link's share of a compliant joint's gravity deflection, from a physical mass model:
    /// δ_j += ∂/∂q_j g·(mass·o_k(q) + R_k(q)·first_moment), k = `link` ≥ j = `joint`, o_k and R_k
    /// the origin and rotation of link k's frame (the frame at its distal end: the DH frame after
    /// joint k, or for a planar chain the link's end with x along the link). `mass` = c_j·m_k and
    /// `first_moment` = c_j·m_k·r_k (r_k the centre of mass in link k's frame) are products with
    /// the joint's compliance c_j; the gauge c_j = 1 (joint unit per mass·length unit) makes them
    /// read as a mass and a first moment (mass × length) of the file's units. Per compliant
    /// joint: each compliant joint carries its own set (format 4 and later).
    GravityMoment {
        /// The compliant joint j (0-based).
        joint: u8,
        /// The link k ≥ j whose weight deflects it (0-based).
        link: u8,
        /// c_j·m_k (a mass in the gauge c_j = 1).
        mass: f64,
        /// c_j·m_k·r_k in link k's frame (a mass × length in the gauge c_j = 1).
        first_moment: [f64; 3],
    },
}

impl Effect {
    /// The first blob format version that can hold this effect.
    pub const fn first_format(&self) -> u16 {
        match self {
            Effect::GravityMoment { .. } => 4,
            _ => 2,
        }
    }
}

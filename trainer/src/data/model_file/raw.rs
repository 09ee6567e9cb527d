//! The model file's TOML as written, before any check (serde's `deny_unknown_fields` names an
//! unknown field and its position).

use super::{exact, AngleUnit, LengthUnit, MeasurementSection};
use crate::data::effects_section::{RawEffect, RawGravity};
use serde::Deserialize;
use std::path::PathBuf;

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawModelFile {
    pub(super) name: Option<String>,
    pub(super) description: Option<String>,
    pub(super) length_unit: LengthUnit,
    pub(super) angle_unit: AngleUnit,
    pub(super) chain: Option<RawChain>,
    pub(super) urdf: Option<RawUrdf>,
    pub(super) planar: Option<RawPlanar>,
    pub(super) measurements: Option<MeasurementSection>,
    pub(super) gravity: Option<RawGravity>,
    #[serde(default)]
    pub(super) effects: Vec<RawEffect>,
}

#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(rename_all = "lowercase")]
pub(super) enum RawConvention {
    Standard,
    Modified,
}

#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(rename_all = "lowercase")]
pub(super) enum RawKind {
    Revolute,
    Prismatic,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawChain {
    pub(super) convention: RawConvention,
    pub(super) joints: Vec<RawJoint>,
    pub(super) base: Option<RawTransform>,
    pub(super) tool: Option<RawTransform>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawJoint {
    pub(super) kind: Option<RawKind>,
    pub(super) a: f64,
    pub(super) alpha: f64,
    pub(super) d: f64,
    #[serde(default)]
    pub(super) theta_offset: f64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawTransform {
    /// `base = { register = true }`: the base is unknown (a tracker's frame) and registered on the data.
    pub(super) register: Option<bool>,
    #[serde(default, deserialize_with = "exact::optional")]
    pub(super) translation: Option<[f64; 3]>,
    #[serde(default, deserialize_with = "exact::optional")]
    pub(super) rpy: Option<[f64; 3]>,
    #[serde(default, deserialize_with = "exact::optional_matrix")]
    pub(super) rotation: Option<[[f64; 3]; 3]>,
    /// `tool = { …, points = [[x, y, z], …] }`: the measured points, offsets in the tool frame
    /// (length unit); absent: one point at the tool origin.
    #[serde(default, deserialize_with = "exact::optional_list")]
    pub(super) points: Option<Vec<[f64; 3]>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawUrdf {
    pub(super) path: PathBuf,
    pub(super) base_link: String,
    pub(super) tip_link: String,
    /// `base = { register = true }`: the data are in a tracker's frame (the chain's base is
    /// `base_link`'s frame otherwise; no other base may be given here).
    pub(super) base: Option<RawTransform>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawPlanar {
    pub(super) lengths: Vec<f64>,
    /// The arm's base in the measurements' plane (length unit), its yaw (angle unit) and the
    /// joint offsets (angle unit): y = R(yaw) k0(q + offsets) + base.
    #[serde(default, deserialize_with = "exact::optional")]
    pub(super) base: Option<[f64; 2]>,
    pub(super) yaw: Option<f64>,
    pub(super) offsets: Option<Vec<f64>>,
}

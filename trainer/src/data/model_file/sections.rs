//! The model file's three ways to give the nominal chain — `[chain]` (a DH table), `[urdf]` and
//! `[planar]` — each read into the nominal model and its joint names.

use super::raw::{RawChain, RawConvention, RawKind, RawPlanar, RawTransform, RawUrdf};
use super::{ImportError, LengthUnit};
use crate::limits::MAX_MAGNITUDE;
use crate::nominal::planar::PlanarFrame;
use crate::nominal::urdf::chain_from_urdf;
use crate::nominal::{rpy, Frame};
use cbd_protocol::{DhChain, DhConvention, DhJoint, JointKind, NominalModel, Transform, MAX_JOINTS};
use std::path::{Path, PathBuf};

/// The nominal model and its joint names.
type Section = (NominalModel, Vec<String>);

/// `[chain] tool = { points = … }`: the tool points (length unit), checked by the rules every list
/// of tool points obeys (`nominal::tool_points::check_tool_points`).
pub(super) fn tool_points(chain: &RawChain, path: &Path) -> Result<Vec<[f64; 3]>, ImportError> {
    let Some(points) = chain.tool.as_ref().and_then(|t| t.points.clone()) else { return Ok(Vec::new()) };
    crate::nominal::tool_points::check_tool_points(&points).map_err(|message| ImportError::Field {
        file: path.to_path_buf(),
        field: "[chain.tool] points".into(),
        message,
    })?;
    Ok(points)
}

fn model_error(path: &Path, message: String) -> ImportError {
    ImportError::Model { file: path.to_path_buf(), message }
}

/// `[chain]`: the DH table with angles in the file's unit (`deg` radians per unit), base and tool.
pub(super) fn dh_chain(chain: &RawChain, deg: f64, path: &Path) -> Result<Section, ImportError> {
    let model_err = |message: String| model_error(path, message);
    if chain.joints.is_empty() || chain.joints.len() > MAX_JOINTS {
        return Err(model_err(format!("[chain] has {} joints; 1 to {MAX_JOINTS} are supported", chain.joints.len())));
    }
    let mut joints = heapless::Vec::<DhJoint, MAX_JOINTS>::new();
    for (i, j) in chain.joints.iter().enumerate() {
        for (name, v) in [("a", j.a), ("alpha", j.alpha), ("d", j.d), ("theta_offset", j.theta_offset)] {
            if !v.is_finite() {
                return Err(model_err(format!("[chain] joint {}: {name} is not finite", i + 1)));
            }
            if v.abs() > MAX_MAGNITUDE {
                return Err(model_err(format!("[chain] joint {}: {name} = {v:e} is beyond ±{MAX_MAGNITUDE:e} (wrong unit?)", i + 1)));
            }
        }
        let kind = match j.kind.unwrap_or(RawKind::Revolute) {
            RawKind::Revolute => JointKind::Revolute,
            RawKind::Prismatic => JointKind::Prismatic,
        };
        let _ = joints.push(DhJoint { kind, a: j.a, alpha: j.alpha * deg, d: j.d, theta_offset: j.theta_offset * deg });
    }
    let base = transform(chain.base.as_ref(), deg, "[chain.base]", path)?;
    let tool = transform(chain.tool.as_ref(), deg, "[chain.tool]", path)?;
    let convention = match chain.convention {
        RawConvention::Standard => DhConvention::Standard,
        RawConvention::Modified => DhConvention::Modified,
    };
    let n = joints.len();
    Ok((
        NominalModel::DhChain(DhChain {
            convention,
            joints,
            base,
            tool,
            effects: cbd_protocol::Effects::NONE,
            tool_points: heapless::Vec::from_slice(&tool_points(chain, path)?).map_err(|_| model_err("too many tool points".into()))?,
        }),
        (1..=n).map(|i| format!("q{i}")).collect(),
    ))
}

/// `[urdf]`: the URDF's chain from `base_link` to `tip_link` as a DH chain in `length_unit`; a
/// relative URDF path is relative to the model file at `path`.
/// The `[urdf]` file's path: as given when absolute, else relative to the model file at `path`.
pub(super) fn urdf_path(u: &RawUrdf, path: &Path) -> PathBuf {
    if u.path.is_absolute() {
        u.path.clone()
    } else {
        path.parent().unwrap_or(Path::new("")).join(&u.path)
    }
}

pub(super) fn urdf_chain(u: &RawUrdf, length_unit: LengthUnit, path: &Path) -> Result<Section, ImportError> {
    let urdf_path = urdf_path(u, path);
    let urdf_err = |message: String| ImportError::Urdf { file: urdf_path.clone(), message };
    let bytes = crate::data::read_capped(&urdf_path, crate::data::MAX_URDF_BYTES, "URDF").map_err(|e| urdf_err(e.without_path()))?;
    let text = String::from_utf8(bytes).map_err(|e| urdf_err(format!("not UTF-8 text: {e}")))?;
    let robot = crate::nominal::urdf::parse(&text).map_err(|e| urdf_err(e.to_string()))?;
    let scale = LengthUnit::M.factor_to(length_unit);
    let conv = chain_from_urdf(&robot, &u.base_link, &u.tip_link, scale).map_err(|e| urdf_err(e.to_string()))?;
    Ok((NominalModel::DhChain(conv.chain), conv.joint_names))
}

/// `[planar]`'s frame: base, yaw and joint offsets (`deg` radians per angle unit); `None` when
/// none is given.
pub(super) fn planar_frame(raw: &RawPlanar, deg: f64, path: &Path) -> Result<Option<PlanarFrame>, ImportError> {
    if raw.base.is_none() && raw.yaw.is_none() && raw.offsets.is_none() {
        return Ok(None);
    }
    let bad = |field: &str, message: String| ImportError::Field { file: path.to_path_buf(), field: format!("[planar] {field}"), message };
    let offsets = raw.offsets.clone().unwrap_or_else(|| vec![0.0; raw.lengths.len()]);
    if offsets.len() != raw.lengths.len() {
        return Err(bad("offsets", format!("{} entries; the arm has {} joints ([planar] lengths)", offsets.len(), raw.lengths.len())));
    }
    let base = raw.base.unwrap_or([0.0; 2]);
    let yaw = raw.yaw.unwrap_or(0.0);
    for (field, values) in [("offsets", &offsets[..]), ("base", &base[..]), ("yaw", &[yaw][..])] {
        if let Some(v) = values.iter().find(|v| !(v.is_finite() && v.abs() <= MAX_MAGNITUDE)) {
            return Err(bad(field, format!("{v:e} is not a finite value within ±{MAX_MAGNITUDE:e}")));
        }
    }
    Ok(Some(PlanarFrame { offsets: offsets.iter().map(|o| o * deg).collect(), base, yaw: yaw * deg }))
}

/// `[planar]`: a planar arm of revolute joints with these link lengths.
pub(super) fn planar(lengths: &[f64], path: &Path) -> Result<Section, ImportError> {
    let model_err = |message: String| model_error(path, message);
    if lengths.is_empty() || lengths.len() > MAX_JOINTS || lengths.iter().any(|l| !l.is_finite()) {
        return Err(model_err(format!("[planar] needs 1 to {MAX_JOINTS} finite lengths")));
    }
    if let Some((i, l)) = lengths.iter().enumerate().find(|(_, l)| l.abs() > MAX_MAGNITUDE) {
        return Err(model_err(format!("[planar] lengths[{}] = {l:e} is beyond ±{MAX_MAGNITUDE:e} (wrong unit?)", i + 1)));
    }
    let n = lengths.len();
    Ok((NominalModel::planar(lengths).expect("checked"), (1..=n).map(|i| format!("q{i}")).collect()))
}

/// A matrix orthonormal within the file's 1e-6 (printed digits) as the blob holds it: itself when
/// orthonormal within a tenth of the protocol's [`cbd_protocol::ROTATION_TOLERANCE`] (the same bits:
/// exact files keep their blobs), else the nearest rotation U Vᵀ of its SVD U Σ Vᵀ — the runtime
/// refuses a base or tool beyond the tolerance.
fn nearest_rotation(m: [[f64; 3]; 3]) -> [[f64; 3]; 3] {
    let departure = (0..3)
        .flat_map(|i| (0..3).map(move |j| (i, j)))
        .map(|(i, j)| ((0..3).map(|k| m[i][k] * m[j][k]).sum::<f64>() - if i == j { 1.0 } else { 0.0 }).abs())
        .fold(0.0, f64::max);
    if departure <= 0.1 * cbd_protocol::ROTATION_TOLERANCE {
        return m;
    }
    let a = faer::Mat::<f64>::from_fn(3, 3, |i, j| m[i][j]);
    let Ok(svd) = a.svd() else { return m };
    let (u, v) = (svd.U(), svd.V());
    std::array::from_fn(|i| std::array::from_fn(|j| (0..3).map(|k| u[(i, k)] * v[(j, k)]).sum()))
}

/// The base or tool transform of `[chain]`; errors name `field` (`[chain.base]`) of `file`.
fn transform(raw: Option<&RawTransform>, deg: f64, field: &str, file: &Path) -> Result<Transform, ImportError> {
    let bad = |message: String| ImportError::Field { file: file.to_path_buf(), field: field.to_string(), message };
    let Some(raw) = raw else { return Ok(Transform::IDENTITY) };
    if raw.points.is_some() && field != "[chain.tool]" {
        return Err(bad("points belong to the tool (`tool = { …, points = [[x, y, z], …] }`)".into()));
    }
    if let Some(register) = raw.register {
        if field != "[chain.base]" {
            return Err(bad("register applies to the base only".into()));
        }
        if raw.translation.is_some() || raw.rpy.is_some() || raw.rotation.is_some() {
            return Err(bad("give either register = true or the base's pose, not both".into()));
        }
        if !register {
            return Err(bad("register = false: omit it (no base means the identity) or give the pose".into()));
        }
        return Ok(Transform::IDENTITY);
    }
    let translation = raw.translation.unwrap_or([0.0; 3]);
    let rotation = match (raw.rpy, raw.rotation) {
        (Some(_), Some(_)) => return Err(bad("give either rpy or rotation, not both".into())),
        (Some([r, p, y]), None) => rpy(r * deg, p * deg, y * deg).rotation(),
        (None, Some(m)) => {
            // Must be a rotation: orthonormal with determinant +1.
            for i in 0..3 {
                for j in 0..3 {
                    let dot: f64 = (0..3).map(|k| m[i][k] * m[j][k]).sum();
                    let want = if i == j { 1.0 } else { 0.0 };
                    if (dot - want).abs() > 1e-6 {
                        return Err(bad(format!("rotation is not orthonormal (rows {} and {} have dot product {dot})", i + 1, j + 1)));
                    }
                }
            }
            let det = m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1]) - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
                + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]);
            if det < 0.0 {
                return Err(bad("rotation has determinant −1 (a reflection)".into()));
            }
            nearest_rotation(m)
        }
        (None, None) => Frame::IDENTITY.rotation(),
    };
    if translation.iter().chain(rotation.iter().flatten()).any(|v| !v.is_finite()) {
        return Err(bad("non-finite value".into()));
    }
    if let Some(v) = translation.iter().find(|v| v.abs() > MAX_MAGNITUDE) {
        return Err(bad(format!("translation {v:e} is beyond ±{MAX_MAGNITUDE:e} (wrong unit?)")));
    }
    Ok(Frame::new(rotation, translation).to_transform())
}

//! The calibrated geometry where ROS users read kinematics (`cbd export`) — a URDF (MoveIt,
//! robot_state_publisher) and the UR description's kinematics file — with what they leave out
//! stated: the flows (and any physical effects) stay in the blob, so on measurements the error of
//! the geometry alone is given beside the full model's.

use super::{ArmModel, Dataset};
use crate::data::model_file::ModelFile;
use crate::error::{Context, Error, Result};
use crate::nominal::export::ur_kinematics::{self, UrKinematics};
use crate::nominal::export::{urdf_patch, urdf_write, LinkFrames};
use crate::nominal::Frame;
use cbd_protocol::{DhChain, NominalModel};
use std::path::Path;

/// Which files an export makes.
#[derive(Debug, Clone, Copy)]
pub struct ExportTargets {
    pub urdf: bool,
    pub ur_kinematics: bool,
}

/// A blob's calibrated geometry, exported: the files' texts, and what the geometry alone is measured with.
pub struct ExportedGeometry {
    /// The URDF's text and what it holds ("… with the calibrated origins of …").
    pub urdf: Option<(String, String)>,
    /// ur_description's kinematics file (its text, hash and the TCP in tool0).
    pub ur_kinematics: Option<UrKinematics>,
    calibrated: DhChain,
    file: ModelFile,
    blob: Vec<u8>,
}

/// Exports the calibrated chain of `blob` (read from `blob_source`) fitted with `arm`'s model
/// file; `urdf_text` is the text of the URDF a `[urdf]` model file names (read by the front).
pub fn export(
    arm: &ArmModel,
    blob: &[u8],
    blob_source: &Path,
    urdf_text: Option<&str>,
    targets: ExportTargets,
) -> Result<ExportedGeometry> {
    let (Some(file), Some(model_path)) = (&arm.file, &arm.path) else {
        return Err(Error::InvalidInput("an export needs a model file (--model)".into()));
    };
    let model = cbd_protocol::decode(blob).context(blob_source.display())?;
    if model.provenance.is_some_and(|p| p.import_frame.is_some()) {
        // The same rule as the model file's joint map below, for a blob that records one (format 9).
        return Err(Error::InvalidInput(format!(
            "{}: fitted to rows read through a joint import or frame ([measurements.joint_map], [planar]): its chain moves with the model's joints, not the controller's (not supported: export a blob fitted without one)",
            blob_source.display()
        )));
    }
    let calibrated = calibrated_chain(file, &model.nominal, model_path, blob_source)?;
    let to_metres = file.length_unit.factor_to(crate::data::model_file::LengthUnit::M);
    let comment = vec![
        format!("Written by cbd export: the calibrated geometry of {} (model {}).", name_of(blob_source), name_of(model_path)),
        "Joint zero offsets are folded into the joint origins. The blob's flows (and any physical effects)".into(),
        "are not in this file: for its full accuracy evaluate or compensate with the blob (runtime, cbd compensate).".into(),
    ];
    let urdf_of = |source: &crate::data::model_file::UrdfSource| {
        urdf_text.ok_or_else(|| Error::Internal(format!("export: the text of {} was not given", source.path.display())))
    };
    let mut urdf = None;
    if targets.urdf {
        urdf = Some(match &file.urdf {
            Some(source) => {
                let scale = 1.0 / to_metres;
                let patched = urdf_patch::patch_urdf_in_frame(
                    urdf_of(source)?,
                    &source.base_link,
                    &source.tip_link,
                    scale,
                    &calibrated,
                    file.register_base,
                )
                .context(source.path.display())?;
                (patched.text, format!("{} with the calibrated origins of {}", source.path.display(), patched.joints.join(", ")))
            }
            None => {
                let robot = file.name.as_deref().unwrap_or("calibrated");
                urdf_write::check_name(&format!("{}: name", model_path.display()), robot)?;
                for (k, name) in file.joint_names.iter().enumerate() {
                    urdf_write::check_name(&format!("{}: joint {}'s name", model_path.display(), k + 1), name)?;
                }
                let limits = file.column_spec().map(|s| s.joint_limits).unwrap_or_default();
                let naming = urdf_write::UrdfNaming { robot, joints: &file.joint_names, to_metres, limits: &limits, comment: &comment };
                let (frames, _) = frames_and_root(file, &calibrated, to_metres, urdf_text)?;
                let base = Frame::from_transform(&calibrated.base);
                (urdf_write::write_urdf(&frames, &base, &naming), format!("{} joints from base_link to tool0", calibrated.joints.len()))
            }
        });
    }
    let mut kinematics = None;
    if targets.ur_kinematics {
        let (frames, root) = frames_and_root(file, &calibrated, to_metres, urdf_text)?;
        kinematics = Some(ur_kinematics::ur_kinematics(&frames, &root, to_metres, &comment)?);
    }
    if model.nominal.effects() != &cbd_protocol::Effects::NONE {
        errln!("note: the blob's physical effects (gravity compliance, transmission, …) are not in the exported geometry; the blob carries them");
    }
    if file.register_base {
        errln!("note: the base was registered on the data (a tracker's frame): the exported base (URDF base_joint, the kinematics file's first origin) is that frame");
    }
    Ok(ExportedGeometry { urdf, ur_kinematics: kinematics, calibrated, file: file.clone(), blob: blob.to_vec() })
}

impl ExportedGeometry {
    /// "URDF alone … ; with the runtime's correction …" on `data`'s rows.
    pub fn geometry_alone(&self, data: &Dataset) -> Result<String> {
        geometry_alone(&self.file, &self.calibrated, &self.blob, &data.imported.measurements, &data.source)
    }
}

/// The file name for a comment line (the full path is the user's machine's business).
fn name_of(path: &std::path::Path) -> String {
    path.file_name().map_or_else(|| path.display().to_string(), |n| n.to_string_lossy().into_owned())
}

/// The blob's chain, checked against the model file's: a spatial (DH or URDF) chain of the same
/// joints, without a joint map, and calibrated — a blob whose chain is the model file's own has no
/// calibrated geometry, and is refused (see `no_calibrated_geometry`).
fn calibrated_chain(file: &ModelFile, blob: &NominalModel, model_path: &Path, blob_source: &Path) -> Result<DhChain> {
    let model_path = model_path.display();
    let NominalModel::DhChain(nominal) = &file.nominal else {
        return Err(Error::InvalidInput(format!(
            "{model_path}: a planar arm ([planar]) has no URDF or UR kinematics export: give a DH table or a URDF model"
        )));
    };
    let NominalModel::DhChain(chain) = blob else {
        return Err(Error::InvalidInput(format!(
            "{}: the blob holds a planar chain; {model_path} is a spatial one",
            blob_source.display()
        )));
    };
    let kinds = |c: &DhChain| c.joints.iter().map(|j| j.kind).collect::<Vec<_>>();
    if kinds(chain) != kinds(nominal) || chain.convention != nominal.convention || chain.tool_points != nominal.tool_points {
        return Err(Error::InvalidInput(format!(
            "{}: its chain ({} joints) is not one of {model_path} ({} joints): fitted with another model file?",
            blob_source.display(),
            chain.joints.len(),
            nominal.joints.len()
        )));
    }
    if file.joint_map.is_some() {
        return Err(Error::InvalidInput(format!(
            "{model_path}: [measurements.joint_map] maps the controller's joints to the model's; an exported file would move with the model's joints, not the controller's (not supported: export from a model file without a joint map)"
        )));
    }
    if chain.joints == nominal.joints && chain.tool == nominal.tool && (chain.base == nominal.base || file.register_base) {
        return Err(no_calibrated_geometry(blob_source, &model_path));
    }
    let mut calibrated = chain.clone();
    calibrated.effects = cbd_protocol::Effects::NONE;
    Ok(calibrated)
}

/// Why a blob of the nominal chain is refused rather than exported with a warning: the file would
/// be the model's own nominal geometry under a name that says "calibrated", which a ROS user loads
/// and sees no change — the "calibration does nothing" trap this command exists to end. A failed
/// command stops a script; a warning line in a log does not.
fn no_calibrated_geometry(blob_source: &Path, model_path: &dyn std::fmt::Display) -> Error {
    Error::InvalidInput(format!(
        "{}: no calibrated geometry in it — its chain is {}'s nominal one (the fit kept the nominal geometry; its whole correction is in the flows, which a URDF cannot carry). Fit with `cbd fit --geometry calibrated` (or `--dh-first`) to export, or use the blob itself (runtime, `cbd compensate`) for its accuracy",
        blob_source.display(),
        model_path
    ))
}

/// The calibrated chain's link frames (slid along their axes toward the nominal's:
/// `LinkFrames::slid_toward`) and the frame the first joint's origin hangs from: for a DH model the
/// model's base frame; for a URDF model the first movable joint's parent link, the links
/// keeping their URDF orientation (ur_description's base_link_inertia for a UR).
fn frames_and_root(file: &ModelFile, calibrated: &DhChain, to_metres: f64, urdf_text: Option<&str>) -> Result<(LinkFrames, Frame)> {
    let Some(source) = &file.urdf else {
        let NominalModel::DhChain(nominal) = &file.nominal else { return Err(Error::Internal("export: a planar model".into())) };
        // Registered (`base = { register = true }`): the nominal in the registered frame, else
        // each link would slide metres along its axis toward the nominal's unregistered place.
        let mut reference = nominal.clone();
        if file.register_base {
            reference.base = calibrated.base;
        }
        let frames = LinkFrames::of_dh_chain(calibrated).slid_toward(&LinkFrames::of_dh_chain(&reference));
        return Ok((frames, Frame::IDENTITY));
    };
    let text = urdf_text.ok_or_else(|| Error::Internal(format!("export: the text of {} was not given", source.path.display())))?;
    // The patched URDF read back: its link frames are the ones written, whatever the URDF's layout.
    let patched =
        urdf_patch::patch_urdf_in_frame(text, &source.base_link, &source.tip_link, 1.0 / to_metres, calibrated, file.register_base)
            .context(source.path.display())?;
    let robot = crate::nominal::urdf::parse(&patched.text).context(source.path.display())?;
    urdf_patch::link_frames(&robot, &source.base_link, &source.tip_link, 1.0 / to_metres).context(source.path.display())
}

/// "URDF alone … ; with the runtime's correction …" on `data`, read from `path`.
fn geometry_alone(file: &ModelFile, calibrated: &DhChain, blob: &[u8], data: &crate::data::Measurements, path: &Path) -> Result<String> {
    use crate::report::stats::ErrorStats;
    let m = data.task_dim;
    let geometric = crate::nominal::positions(&NominalModel::DhChain(calibrated.clone()), &data.joints, m);
    let full = crate::predict::evaluate_blob(blob, &data.joints).context(path.display())?;
    let nominal = crate::nominal::positions(&file.nominal, &data.joints, m);
    let [g, f, n] = [&geometric, &full, &nominal].map(|p| ErrorStats::of_positions(p, &data.positions, m).mean);
    let unit = file.length_unit.name();
    let [g, f, n] = [g, f, n].map(readable);
    Ok(format!(
        "{} ({} rows), mean error: URDF alone {g} {unit}; with the runtime's correction {f} {unit} (nominal {n} {unit})",
        path.display(),
        data.len()
    ))
}

/// An error as the geometry-alone line prints it: three decimals from 0.01 up (mm data), three
/// significant digits below (a metre model's 6.04e-5 m, not 0.000 m).
fn readable(v: f64) -> String {
    if v == 0.0 || !v.is_finite() || v.abs() >= 0.01 {
        format!("{v:.3}")
    } else {
        format!("{v:.2e}")
    }
}

//! `cbd export`: the calibrated geometry where ROS users read kinematics (`crate::face::export`) —
//! a URDF and the UR description's kinematics file — with what they leave out stated: with
//! `--data` the error of the geometry alone is printed beside the full model's.

use crate::error::{Error, Result};
use crate::face::{ArmModel, Dataset, ExportTargets};
use std::path::PathBuf;

#[derive(Debug, clap::Args)]
pub struct ExportArgs {
    /// The model file the blob was fitted with (units and names; from a `[urdf]` model, its URDF is
    /// the file rewritten).
    #[arg(long)]
    pub model: PathBuf,
    /// A blob whose chain was calibrated (`cbd fit --geometry calibrated`, or `--dh-first`).
    #[arg(long)]
    pub blob: PathBuf,
    /// Write a URDF whose joint origins carry the calibrated geometry (joint offsets folded in;
    /// base and tool as fixed joints). From a `[urdf]` model: that file with only those origins changed.
    #[arg(long)]
    pub urdf: Option<PathBuf>,
    /// Write ur_description's kinematics file (kinematics_parameters_file: six joint origins, a hash).
    #[arg(long)]
    pub ur_kinematics: Option<PathBuf>,
    /// Measurements (CSV, e.g. a test set): print the error of the exported geometry alone beside
    /// the full model's (the runtime's correction).
    #[arg(long)]
    pub data: Option<PathBuf>,
}

pub fn run(args: ExportArgs) -> Result<()> {
    if args.urdf.is_none() && args.ur_kinematics.is_none() {
        return Err(Error::InvalidInput("nothing to export: give --urdf OUT.urdf and/or --ur-kinematics OUT.yaml".into()));
    }
    crate::io::check_paths(
        &[("--model", Some(&args.model)), ("--blob", Some(&args.blob)), ("--data", args.data.as_deref())],
        &[("--urdf", args.urdf.as_deref()), ("--ur-kinematics", args.ur_kinematics.as_deref())],
    )?;
    let arm = ArmModel::from_file(&args.model, crate::data::model_file::load_model_file(&args.model)?)?;
    let blob = crate::face::read_blob(&args.blob)?;
    // A `[urdf]` model's URDF is the file rewritten (and its link frames the ones read back).
    let urdf_text = match arm.file.as_ref().and_then(|f| f.urdf.as_ref()) {
        Some(source) => {
            let text = crate::data::read_capped(&source.path, crate::data::MAX_URDF_BYTES, "URDF")?;
            Some(String::from_utf8(text).map_err(|e| Error::Urdf(format!("{}: not UTF-8 text: {e}", source.path.display())))?)
        }
        None => None,
    };
    let targets = ExportTargets { urdf: args.urdf.is_some(), ur_kinematics: args.ur_kinematics.is_some() };
    let exported = crate::face::export(&arm, &blob, &args.blob, urdf_text.as_deref(), targets)?;
    let mut report = Vec::new();
    if let (Some(out), Some((text, what))) = (&args.urdf, &exported.urdf) {
        crate::cli::write_atomically(out, text.as_bytes())?;
        report.push(format!("URDF written to {}: {what}", out.display()));
    }
    if let (Some(out), Some(k)) = (&args.ur_kinematics, &exported.ur_kinematics) {
        crate::cli::write_atomically(out, k.text.as_bytes())?;
        let [x, y, z] = k.tcp.translation();
        let [r, p, yaw] = crate::nominal::export::rpy_of(&k.tcp.rotation());
        report.push(format!("UR kinematics written to {} (hash {})", out.display(), k.hash));
        report.push(format!(
            "  TCP in tool0 (the measured tool point: set it as the tool): xyz [{x:.6}, {y:.6}, {z:.6}] m, rpy [{r:.6}, {p:.6}, {yaw:.6}] rad"
        ));
    }
    if let Some(path) = &args.data {
        report.push(exported.geometry_alone(&Dataset::read(path, &arm.spec)?)?);
    }
    // Said once everything is done: a later failure (--data) writes no file, so no line claims one.
    for line in report {
        outln!("{line}");
    }
    Ok(())
}

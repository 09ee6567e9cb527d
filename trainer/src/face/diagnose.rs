//! A residual diagnosed (`cbd diagnose`): structure left in it traced to physical effects of the
//! library, selected out of sample, with the error before and after on held-out rows.

use super::{ArmModel, Dataset, PipelineOptions};
use crate::data::model_file::AngleUnit;
use crate::diagnose::{report, DiagnoseOptions};
use crate::error::{Context, Error, Result};
use crate::nominal::planar::PlanarFrame;
use cbd_protocol::NominalModel;
use std::path::Path;

/// What a diagnosis is asked to try: the flags of `cbd diagnose` but its files, and the keywords of
/// the Python package's `diagnose` (one set of defaults).
#[derive(Debug, Clone, clap::Args, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DiagnoseSettings {
    /// Transmission harmonics 1..H tried per joint.
    #[arg(long, default_value_t = defaults::harmonics())]
    #[serde(default = "defaults::harmonics")]
    pub harmonics: u8,
    /// Cross-validation folds of the selection.
    #[arg(long, default_value_t = defaults::folds())]
    #[serde(default = "defaults::folds")]
    pub folds: usize,
    /// Smallest relative drop of the cross-validated RMS error for an effect to be kept.
    #[arg(long, default_value_t = defaults::margin())]
    #[serde(default = "defaults::margin")]
    pub margin: f64,
    /// Skip the CbD rows of the table (two CbD fits).
    #[arg(long)]
    #[serde(default)]
    pub no_cbd: bool,
    /// CbD's hyperparameters and scheme for the CbD rows, as in `cbd fit`.
    #[command(flatten)]
    #[serde(flatten)]
    pub solver: PipelineOptions,
}

/// The flags' defaults, one source for the command line (clap) and the Python package's keyword
/// arguments (serde): `cli::settings_tests` checks that both read the same arguments from nothing.
mod defaults {
    pub fn harmonics() -> u8 {
        3
    }

    pub fn folds() -> usize {
        5
    }

    pub fn margin() -> f64 {
        0.05
    }
}

impl DiagnoseSettings {
    /// Rejects out-of-range values before any work, naming the flag.
    pub fn validate(&self) -> Result<()> {
        if !(1..=16).contains(&self.harmonics) {
            return Err(Error::InvalidInput(format!("--harmonics must be between 1 and 16, got {}", self.harmonics)));
        }
        if self.folds < 2 {
            return Err(Error::InvalidInput(format!("--folds must be at least 2, got {}", self.folds)));
        }
        if !(self.margin >= 0.0 && self.margin < 1.0) {
            return Err(Error::InvalidInput(format!("--margin must be in [0, 1), got {}", self.margin)));
        }
        Ok(())
    }
}

/// A diagnosis with what its table, JSON, figures and corrected model file are written in.
pub struct Diagnosis {
    pub diagnosis: crate::diagnose::Diagnosis,
    /// The base registered on the rows, when the model file declares it unknown.
    pub registration: Option<crate::parametric::base_registration::Registration>,
    /// The nominal the diagnosis started from (in the registered frame).
    nominal: NominalModel,
    /// The diagnosed rows (the corrected model file is checked against them).
    data: crate::data::Measurements,
    /// The diagnosed rows' source in messages.
    source: std::path::PathBuf,
    /// The model file's length and angle units (without one, the data's: radians).
    length: &'static str,
    angle: AngleUnit,
    /// The model file's joint names (`None`: the built-in arm, no model file).
    joint_names: Option<Vec<String>>,
}

/// Diagnoses `data` against `arm`'s nominal (its base registered on them when the model file
/// declares it unknown); `test` (else a fifth of `data`) gives the before/after table.
pub fn diagnose(arm: &ArmModel, data: &Dataset, test: Option<&Dataset>, settings: &DiagnoseSettings) -> Result<Diagnosis> {
    settings.validate()?;
    let mut nominal = arm.nominal.clone();
    let read = |data: &Dataset, nominal: &mut NominalModel, register: bool| {
        let (imported, path) = (&data.imported, data.source.as_path());
        for w in imported.warnings(path) {
            errln!("warning: {w}");
        }
        let registration = match register {
            true => super::register_base_if_unknown(arm, nominal, &imported.measurements, path)?,
            false => None,
        };
        for w in crate::data::preparation::nominal_warnings(nominal, &imported.measurements, &imported.lines, path, arm.register_base())? {
            errln!("warning: {w}");
        }
        Ok::<_, Error>(registration)
    };
    let registration = read(data, &mut nominal, true)?;
    let (source, data) = (data.source.clone(), data.imported.measurements.clone());
    // The CbD rows fit all training rows: refuse up front what cannot fit in memory.
    let threads = match settings.no_cbd {
        false => crate::memory::check_fit_of(&source, data.len(), data.task_dim, "--no-cbd skips the CbD rows")?,
        true => crate::memory::worker_threads(),
    };
    let test = match test {
        Some(test) => {
            read(test, &mut nominal.clone(), false)?;
            Some(&test.imported.measurements)
        }
        None => None,
    };
    let mut options = DiagnoseOptions::default();
    options.library.harmonics = settings.harmonics;
    options.structure.harmonics = settings.harmonics;
    options.selection.folds = settings.folds;
    options.selection.margin = settings.margin;
    let mut pipeline = settings.solver.settings()?;
    pipeline.solver.verbose = false;
    pipeline.solver.threads = threads;
    let diagnosis = crate::memory::on_workers(threads, || {
        let fitter = super::peers::cbd_correction(&pipeline);
        let cbd: Option<crate::evaluation::correction::CorrectionFitter> = if settings.no_cbd { None } else { Some(&fitter) };
        crate::diagnose::diagnose(&nominal, &data, test, cbd, &options)
    })?;
    let file = arm.file.as_ref();
    Ok(Diagnosis {
        diagnosis,
        registration,
        nominal,
        data,
        source,
        // The file's units; without a model file, the data's (joint angles in radians).
        length: file.map_or("length units", |m| m.length_unit.name()),
        angle: file.map_or(AngleUnit::Rad, |m| m.angle_unit),
        joint_names: file.map(|m| m.joint_names.clone()),
    })
}

impl Diagnosis {
    fn units(&self) -> report::Units<'_> {
        report::Units { length: self.length, angle: self.angle }
    }

    /// The table `cbd diagnose` prints.
    pub fn text(&self) -> String {
        let d = &self.diagnosis;
        report::text(d, &d.model_start, &self.units())
    }

    /// `cbd diagnose --json`'s value.
    pub fn to_json(&self) -> serde_json::Value {
        let d = &self.diagnosis;
        let mut json = report::to_json(d, &d.model_start, &self.units());
        if let Some(r) = &self.registration {
            json["registered_base"] = r.to_json();
        }
        json
    }

    /// Writes the residual-against-joint figures (PNG and SVG) into `dir`; the number of files.
    pub fn write_figures(&self, dir: &Path) -> Result<usize> {
        let d = &self.diagnosis;
        // Joint axes in the file's units: its angle unit for revolute joints, its length unit otherwise.
        let (names, scales): (Vec<String>, Vec<f64>) = (0..self.nominal.n_joints())
            .map(|j| {
                let name = self.joint_names.as_ref().and_then(|n| n.get(j).cloned()).unwrap_or_else(|| format!("q{}", j + 1));
                match (self.joint_names.is_some(), self.nominal.is_revolute(j)) {
                    (true, true) => (format!("{name} ({})", self.angle.name()), 1.0 / self.angle.radians()),
                    (false, true) => (format!("{name} (rad)"), 1.0),
                    (_, false) => (format!("{name} ({})", self.length), 1.0),
                }
            })
            .unzip();
        Ok(report::plots(dir, d, &d.model_start, &names, &scales, self.length)?.len())
    }

    /// The text of `arm`'s model file with the geometric corrections in its DH table and the effects
    /// found in `[[effects]]`, to be written at `path` (named in its header); checked to read back
    /// to the model the diagnosis evaluated. `None`: the built-in arm has no model file.
    pub fn model_file(&self, arm: &ArmModel, path: &Path) -> Result<Option<String>> {
        let Some(mut file) = arm.file.clone() else { return Ok(None) };
        let (d, data) = (&self.diagnosis, &self.data);
        // A registered base is written as the pose the diagnosis found.
        file.register_base = false;
        // A [planar] file holds lengths and effects in a frame (base, yaw, joint offsets); the
        // data were read into the file's frame, so the diagnosed frame composes with it.
        let planar = matches!(self.nominal, NominalModel::PlanarChain { .. });
        let inner = if planar {
            let (chain, inner) = crate::nominal::planar::as_planar_in_frame(&d.model_after).ok_or_else(|| {
                Error::Internal(format!("internal: --write-model {}: the diagnosed planar arm is not a planar DH form", path.display()))
            })?;
            let outer = file.planar_frame.clone().unwrap_or(PlanarFrame { offsets: vec![0.0; chain.n_joints()], base: [0.0; 2], yaw: 0.0 });
            file.planar_frame = Some(outer.then(&inner));
            file.nominal = chain;
            Some(inner)
        } else {
            file.nominal = d.model_after.clone();
            None
        };
        let found: Vec<&str> = d.found.iter().map(|f| f.name.as_str()).collect();
        let header = format!(
            "{} with the corrections `cbd diagnose` found on {} ({} rows): {}.\nFit the nonparametric correction on top: cbd fit --model {} ...",
            arm.path.as_ref().map(|p| p.display().to_string()).unwrap_or_default(),
            self.source.display(),
            d.train_rows,
            if found.is_empty() { "none".to_string() } else { found.join(", ") },
            path.display()
        );
        let text = crate::data::model_file::write_model_file(&file, &header);
        // What is written must read back to the model the diagnosis evaluated.
        let back = crate::data::model_file::parse_model_file(&text, path).context("internal: the written model file does not read back")?;
        let gap = match &inner {
            Some(frame) => planar_gap(&back.nominal, frame, &d.model_after, data),
            None => max_position_gap(&back.nominal, &d.model_after, data),
        };
        if gap > 1e-9 * (1.0 + data.positions.iter().fold(0.0f64, |a, v| a.max(v.abs()))) {
            let why = if planar {
                " (a [planar] file turns the chain at q + offsets before its effects: an encoder scale on a joint whose offset was corrected cannot be written exactly)"
            } else {
                ""
            };
            return Err(Error::InvalidInput(format!(
                "--write-model {}: the written model file differs from the diagnosed model by {gap:.3e} at the data{why}",
                path.display()
            )));
        }
        Ok(Some(text))
    }
}

/// As [`max_position_gap`] for a planar chain in `frame` against the diagnosed DH form `b`.
fn planar_gap(chain: &NominalModel, frame: &PlanarFrame, b: &NominalModel, data: &crate::data::Measurements) -> f64 {
    let joints = frame.chain_joints(&data.joints);
    let n = data.n_joints;
    (0..data.len())
        .map(|i| {
            let pa = frame.from_chain(&crate::diagnose::kinematics::position(chain, &joints[i * n..(i + 1) * n], 2, 0));
            let pb = crate::diagnose::kinematics::position(b, data.joints(i), 2, 0);
            pa.iter().zip(&pb).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max)
        })
        .fold(0.0, f64::max)
}

/// Largest position difference between two nominal models over the rows of `data`.
fn max_position_gap(a: &NominalModel, b: &NominalModel, data: &crate::data::Measurements) -> f64 {
    let m = data.task_dim;
    (0..data.len())
        .map(|i| {
            use crate::diagnose::kinematics::{point_of_row, position};
            let (pa, pb) = (position(a, data.joints(i), m, point_of_row(a, i)), position(b, data.joints(i), m, point_of_row(b, i)));
            pa.iter().zip(&pb).take(m).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max)
        })
        .fold(0.0, f64::max)
}

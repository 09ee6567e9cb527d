//! `cbd diagnose`: structure left in the residual, traced to physical effects of the library,
//! selected out of sample, reported with the error before and after on held-out rows.

use crate::cli::{ArmModel, ModelArgs};
use crate::data::model_file::AngleUnit;
use crate::diagnose::{diagnose, report, DiagnoseOptions};
use crate::error::{Context, Error, Result};
use crate::nominal::planar::PlanarFrame;
use std::path::PathBuf;

#[derive(Debug, clap::Args, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DiagnoseArgs {
    #[command(flatten)]
    #[serde(flatten)]
    pub model: ModelArgs,
    /// Measurements to diagnose (CSV, the model file's columns).
    #[arg(long)]
    pub data: PathBuf,
    /// Held-out measurements for the before/after table (never used for fitting or selection).
    /// Without it, a fifth of --data is held out.
    #[arg(long)]
    pub test: Option<PathBuf>,
    /// Write the diagnosis as JSON here.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Write the residual-against-joint figure (PNG and SVG) into this directory.
    #[arg(long)]
    pub plots: Option<PathBuf>,
    /// Write the model file with the geometric corrections in its DH table and the effects
    /// found in [[effects]] (needs --model).
    #[arg(long)]
    pub write_model: Option<PathBuf>,
    /// Transmission harmonics 1..H tried per joint.
    #[arg(long, default_value_t = crate::cli::args::defaults::harmonics())]
    #[serde(default = "crate::cli::args::defaults::harmonics")]
    pub harmonics: u8,
    /// Cross-validation folds of the selection.
    #[arg(long, default_value_t = crate::cli::args::defaults::folds())]
    #[serde(default = "crate::cli::args::defaults::folds")]
    pub folds: usize,
    /// Smallest relative drop of the cross-validated RMS error for an effect to be kept.
    #[arg(long, default_value_t = crate::cli::args::defaults::margin())]
    #[serde(default = "crate::cli::args::defaults::margin")]
    pub margin: f64,
    /// Skip the CbD rows of the table (two CbD fits).
    #[arg(long)]
    #[serde(default)]
    pub no_cbd: bool,
    /// CbD's hyperparameters and scheme for the CbD rows, as in `cbd fit`.
    #[command(flatten)]
    #[serde(flatten)]
    pub solver: crate::face::PipelineOptions,
}

/// The flags' values, before any work.
fn check_flags(args: &DiagnoseArgs) -> Result<()> {
    if !(1..=16).contains(&args.harmonics) {
        return Err(Error::InvalidInput(format!("--harmonics must be between 1 and 16, got {}", args.harmonics)));
    }
    if args.folds < 2 {
        return Err(Error::InvalidInput(format!("--folds must be at least 2, got {}", args.folds)));
    }
    if !(args.margin >= 0.0 && args.margin < 1.0) {
        return Err(Error::InvalidInput(format!("--margin must be in [0, 1), got {}", args.margin)));
    }
    if args.write_model.is_some() && args.model.model.is_none() {
        return Err(Error::InvalidInput("--write-model needs --model (the file the corrections are written into)".into()));
    }
    Ok(())
}

pub fn run(args: DiagnoseArgs) -> Result<()> {
    check_flags(&args)?;
    crate::io::check_paths(
        &[("--model", args.model.model.as_deref()), ("--data", Some(&args.data)), ("--test", args.test.as_deref())],
        &[("--json", args.json.as_deref()), ("--write-model", args.write_model.as_deref())],
    )?;
    if let Some(dir) = &args.plots {
        crate::io::check_output_dir("--plots", dir)?;
    }
    let arm = ArmModel::read(&args.model)?;
    let data = crate::data::csv_import::read_measurements(&args.data, &arm.spec)?;
    let test = args.test.as_ref().map(|path| crate::data::csv_import::read_measurements(path, &arm.spec)).transpose()?;
    let json = diagnose_measurements(&args, &arm, data, test)?;
    if let Some(path) = &args.json {
        let text = serde_json::to_string_pretty(&json).map_err(Error::JsonOutput)?;
        crate::cli::write_atomically(path, text.as_bytes())?;
    }
    Ok(())
}

/// The diagnosis `cbd diagnose` runs, on measurements already read with `arm`'s column spec
/// (`args.data` and `args.test` name them in messages and are not read; `args.model` is not read
/// again — `arm` is it): prints its table, writes `--plots` and `--write-model`, and returns the
/// `--json` value (not written here). One function for the command and the Python package.
pub fn diagnose_measurements(
    args: &DiagnoseArgs,
    arm: &ArmModel,
    data: crate::data::csv_import::ImportedMeasurements,
    test: Option<crate::data::csv_import::ImportedMeasurements>,
) -> Result<serde_json::Value> {
    check_flags(args)?;
    let (mut nominal, arm) = (arm.nominal.clone(), arm);
    type Read = (crate::data::Measurements, Option<crate::parametric::base_registration::Registration>);
    let read = |imported: crate::data::csv_import::ImportedMeasurements,
                path: &PathBuf,
                nominal: &mut cbd_protocol::NominalModel,
                register: bool|
     -> Result<Read> {
        for w in imported.warnings(path) {
            errln!("warning: {w}");
        }
        let registration = match register {
            true => crate::cli::register_base_if_unknown(arm, nominal, &imported.measurements, path)?,
            false => None,
        };
        for w in crate::data::nominal_check::nominal_warnings(&nominal, &imported.measurements, &imported.lines, path, arm.register_base())?
        {
            errln!("warning: {w}");
        }
        Ok((imported.measurements, registration))
    };
    let (data, registration) = read(data, &args.data, &mut nominal, true)?;
    // The CbD rows fit all training rows: refuse up front what cannot fit in memory.
    let threads = match args.no_cbd {
        false => crate::cli::memory::check_fit_of(&args.data, &data, "--no-cbd skips the CbD rows")?,
        true => crate::workers::worker_threads(),
    };
    let test = match test {
        Some(test) => Some(read(test, args.test.as_ref().unwrap_or(&args.data), &mut nominal.clone(), false)?.0),
        None => None,
    };
    let mut options = DiagnoseOptions::default();
    options.library.harmonics = args.harmonics;
    options.structure.harmonics = args.harmonics;
    options.selection.folds = args.folds;
    options.selection.margin = args.margin;
    let mut settings = args.solver.settings()?;
    settings.solver.verbose = false;
    settings.solver.threads = threads;
    let d = crate::workers::on_workers(threads, || {
        let fitter = crate::cli::args::cbd_fitter(&settings);
        let cbd: Option<crate::evaluation::correction::CorrectionFitter> = if args.no_cbd { None } else { Some(&fitter) };
        diagnose(&nominal, &data, test.as_ref(), cbd, &options)
    })?;
    let model_file = arm.file.as_ref();
    let unit = model_file.as_ref().map(|m| m.length_unit.name()).unwrap_or("length units");
    // The file's units; without a model file, the data's (joint angles in radians).
    let units = report::Units { length: unit, angle: model_file.as_ref().map(|m| m.angle_unit).unwrap_or(AngleUnit::Rad) };
    outln!("{}", report::text(&d, &d.model_start, &units));
    let mut json = report::to_json(&d, &d.model_start, &units);
    if let Some(r) = &registration {
        json["registered_base"] = r.to_json();
    }
    if let Some(dir) = &args.plots {
        // Joint axes in the file's units: its angle unit for revolute joints, its length unit otherwise.
        let (names, scales): (Vec<String>, Vec<f64>) = (0..nominal.n_joints())
            .map(|j| {
                let name = model_file.as_ref().and_then(|m| m.joint_names.get(j).cloned()).unwrap_or_else(|| format!("q{}", j + 1));
                match (&model_file, nominal.is_revolute(j)) {
                    (Some(m), true) => (format!("{name} ({})", m.angle_unit.name()), 1.0 / m.angle_unit.radians()),
                    (None, true) => (format!("{name} (rad)"), 1.0),
                    (_, false) => (format!("{name} ({unit})"), 1.0),
                }
            })
            .unzip();
        let files = report::plots(dir, &d, &d.model_start, &names, &scales, unit)?;
        outln!("figures written to {} ({} files)", dir.display(), files.len());
    }
    if let (Some(path), Some(mut file)) = (&args.write_model, model_file.cloned()) {
        // A registered base is written as the pose the diagnosis found.
        file.register_base = false;
        // A [planar] file holds lengths and effects in a frame (base, yaw, joint offsets); the
        // data were read into the file's frame, so the diagnosed frame composes with it.
        let planar = matches!(nominal, cbd_protocol::NominalModel::PlanarChain { .. });
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
            args.model.model.as_ref().map(|p| p.display().to_string()).unwrap_or_default(),
            args.data.display(),
            d.train_rows,
            if found.is_empty() { "none".to_string() } else { found.join(", ") },
            path.display()
        );
        let text = crate::data::model_file::write_model_file(&file, &header);
        // What is written must read back to the model the diagnosis evaluated.
        let back = crate::data::model_file::parse_model_file(&text, path).context("internal: the written model file does not read back")?;
        let gap = match &inner {
            Some(frame) => planar_gap(&back.nominal, frame, &d.model_after, &data),
            None => max_position_gap(&back.nominal, &d.model_after, &data),
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
        crate::cli::write_atomically(path, text.as_bytes())?;
        outln!("model with the found effects written to {}", path.display());
    }
    Ok(json)
}

/// As [`max_position_gap`] for a planar chain in `frame` against the diagnosed DH form `b`.
fn planar_gap(
    chain: &cbd_protocol::NominalModel,
    frame: &PlanarFrame,
    b: &cbd_protocol::NominalModel,
    data: &crate::data::Measurements,
) -> f64 {
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
fn max_position_gap(a: &cbd_protocol::NominalModel, b: &cbd_protocol::NominalModel, data: &crate::data::Measurements) -> f64 {
    let m = data.task_dim;
    (0..data.len())
        .map(|i| {
            use crate::diagnose::kinematics::{point_of_row, position};
            let (pa, pb) = (position(a, data.joints(i), m, point_of_row(a, i)), position(b, data.joints(i), m, point_of_row(b, i)));
            pa.iter().zip(&pb).take(m).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max)
        })
        .fold(0.0, f64::max)
}

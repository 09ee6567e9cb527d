//! What several commands share: their argument groups (the model file; the pipeline's options are
//! the face's, `crate::face::PipelineOptions`) and the helpers behind them (the model file read from
//! its flag, CbD's fit for those options, a blob that does not fit its model). Commands import from
//! here, from `blob_rows` (a blob read and evaluated on rows) and from `cli` itself, never from each other.

use crate::error::{Error, Result};

/// The nominal model: a model file, or the built-in planar RR arm.
#[derive(Debug, Clone, clap::Args, serde::Deserialize)]
pub struct ModelArgs {
    /// Model file (TOML: DH table or URDF, units, CSV columns). Without it: the paper's RR arm,
    /// CSV columns q1, q2 (radians), x, y.
    #[arg(long)]
    pub model: Option<std::path::PathBuf>,
}

impl crate::face::ArmModel {
    /// Reads `args.model` (the command's one parse of its model file), or takes the built-in RR arm.
    /// Reading the file is the command's part: the face's own functions take the arm parsed.
    pub fn read(args: &ModelArgs) -> Result<Self> {
        match &args.model {
            Some(path) => Self::from_file(path, crate::data::model_file::load_model_file(path)?),
            None => Ok(Self::builtin_rr()),
        }
    }
}

/// A list flag given as one value or as a list (`effect="…"` or `effect=["…", "…"]`).
pub fn one_or_many<'de, D: serde::Deserializer<'de>>(deserializer: D) -> std::result::Result<Vec<String>, D::Error> {
    #[derive(serde::Deserialize)]
    #[serde(untagged)]
    enum OneOrMany {
        One(String),
        Many(Vec<String>),
    }
    Ok(match <OneOrMany as serde::Deserialize>::deserialize(deserializer)? {
        OneOrMany::One(v) => vec![v],
        OneOrMany::Many(v) => v,
    })
}

/// The flags' defaults, one source for the command line (clap) and the Python package's keyword
/// arguments (serde): `cli::settings_tests` checks that both read the same arguments from nothing.
pub mod defaults {
    pub fn harmonics() -> u8 {
        3
    }

    pub fn folds() -> usize {
        5
    }

    pub fn margin() -> f64 {
        0.05
    }

    pub fn robot() -> String {
        "rr".into()
    }

    pub fn sampling() -> String {
        "grid".into()
    }

    pub fn grid() -> usize {
        16
    }

    pub fn count() -> usize {
        3000
    }

    pub fn seed() -> u64 {
        1
    }
}

/// CbD through the one calibration pipeline (`crate::calibrate`) on whatever base model the caller
/// gives (nominal, DH-calibrated, with effects), deformed as given (`--geometry nominal`): the blob
/// `cbd fit --geometry nominal` writes for that model, data and flags.
pub fn cbd_fitter(
    settings: &crate::calibrate::Settings,
) -> impl Fn(&cbd_protocol::NominalModel, &crate::data::Measurements) -> crate::Result<crate::evaluation::correction::FittedCorrection> {
    let settings = crate::calibrate::Settings { geometry: crate::calibrate::Geometry::Nominal, ..settings.clone() };
    move |nominal: &cbd_protocol::NominalModel,
          data: &crate::data::Measurements|
          -> crate::Result<crate::evaluation::correction::FittedCorrection> {
        let calibration = crate::calibrate::calibrate(nominal, data, &settings)?;
        crate::face::print_calibration(&calibration, !settings.solver.verbose);
        let mut note = calibration.describe_hyperparameters();
        if let Some(e) = &calibration.evidence {
            note += &format!("; evidence {:.2} on {} rows ({:.2} s)", e.log_evidence, e.rows_used, e.seconds);
        }
        // Which member of the prior family the row used (docs/DESIGN.md §16).
        let member = if calibration.hyperparameters.configuration.is_some() { "with the configuration field" } else { "CbD's two fields" };
        note += &match &calibration.configuration {
            Some(f) => format!(
                "; prior: {member} (configuration field {} by evidence: {:.1} → {:.1}, margin {:.1})",
                if f.chosen { "chosen" } else { "not chosen" },
                f.plain_log_evidence,
                f.with_term_log_evidence,
                f.margin
            ),
            None => format!("; prior: {member}"),
        };
        note += &format!("; {} ({})", calibration.scheme.label(), calibration.scheme.chosen_by);
        for w in &calibration.warnings {
            note += &format!("; warning: {w}");
        }
        let blob = calibration.fit.blob;
        let predictor: crate::evaluation::correction::Predictor =
            Box::new(move |joints: &[f64]| crate::predict::evaluate_blob(&blob, joints).unwrap_or_else(|_| vec![f64::NAN; joints.len()]));
        Ok(crate::evaluation::correction::FittedCorrection {
            noise_sigma: Some(calibration.hyperparameters.sigma),
            ..crate::evaluation::correction::FittedCorrection::new(predictor, note)
        })
    }
}

/// A blob that does not fit the model file (or the built-in arm) it is used with: one message
/// naming both, for `eval` and `compensate`.
pub fn blob_misfit(blob: &std::path::Path, model: &ModelArgs, why: String) -> Error {
    let file = model.model.as_ref().map_or("the built-in RR arm (no --model given)".to_string(), |p| p.display().to_string());
    Error::InvalidInput(format!("{}: does not fit {file}: {why}", blob.display()))
}

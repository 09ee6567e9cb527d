//! `cbd check`: does a calibration still hold on fresh poses? The fresh residual (measured − the
//! blob's prediction) is tested against the blob's own posterior predictive distribution
//! ([`covariance`]) by its Mahalanobis statistic and χ² law ([`statistic`]), after the fresh rows'
//! rigid frame when the tracker was set up anew ([`register`]). docs/DESIGN.md "cbd check".

pub mod covariance;
pub mod name;
pub mod register;
pub mod statistic;
pub mod update;

use crate::data::Measurements;
use cbd_protocol::Model;
use register::RegisteredFrame;
use statistic::Statistic;

/// The test's answer at level α.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Verdict {
    /// p ≥ α: the fresh residual is what the calibration predicts for its own errors.
    Holds,
    /// p < α.
    Changed,
}

/// What a check found.
#[derive(Debug, Clone)]
pub struct Check {
    pub statistic: Statistic,
    pub verdict: Verdict,
    /// The fresh rows' frame, when registered.
    pub frame: Option<RegisteredFrame>,
    /// The measured positions the residual was taken from (in the blob's frame when registered),
    /// the data's length unit, row-major.
    pub measured: Vec<f64>,
    /// The residual the statistic was taken of (internal units), its covariance C and the
    /// registered frame's tangent: what naming the change fits ([`name`]).
    pub residual: Vec<f64>,
    pub covariance: faer::Mat<f64>,
    pub tangent: Option<faer::Mat<f64>>,
}

/// Why a check could not be made (the CLI names the files).
#[derive(Debug, Clone, PartialEq)]
pub enum CheckError {
    /// The blob records no σ (format 6 or older).
    NoSigma,
    /// Fewer rows than the frame's degrees of freedom, or no degree of freedom left.
    TooFewRows { rows: usize, needed: usize },
    /// The points lie on a line: no unique frame.
    DegenerateFrame,
    /// Registration on planar data.
    PlanarFrame,
    /// The predictive covariance (or the frame's part of it) is not positive definite.
    NotPositiveDefinite,
}

impl std::fmt::Display for CheckError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            CheckError::NoSigma => write!(
                f,
                "records no noise σ (a blob of format 6 or older): the check sets the fresh residual against the calibration's own σ; fit the blob again with this version"
            ),
            CheckError::TooFewRows { rows, needed } => {
                write!(f, "{rows} fresh rows; a check with the frame registered needs at least {needed} (the frame's degrees of freedom)")
            }
            CheckError::DegenerateFrame => write!(f, "the fresh rows' points lie on a line: their frame cannot be registered"),
            CheckError::PlanarFrame => write!(f, "registering the fresh rows' frame needs 3-D positions"),
            CheckError::NotPositiveDefinite => write!(
                f,
                "the blob's predictive covariance at the fresh rows is not positive definite: usually its σ lies so far below its \
                 kernels' scale (rows measured without noise, such as simulated ones) that double precision cannot resolve the \
                 fresh rows' posterior; the check needs the measurements' real noise: fit again with --sigma (the instrument's \
                 noise per coordinate)"
            ),
        }
    }
}

/// How a check is made.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CheckOptions {
    /// The level: "changed" when p < alpha.
    pub alpha: f64,
    /// Register the fresh rows' rigid frame first.
    pub register: bool,
    /// The blob's chain is DH-calibrated: its parameters' uncertainty is part of C.
    pub geometry: bool,
}

/// The check of `fresh` (measured positions, the data's = the model's length unit) against
/// `predicted` (the blob's evaluation at the same rows).
pub fn check(model: &Model, fresh: &Measurements, predicted: &[f64], options: CheckOptions) -> Result<Check, CheckError> {
    let CheckOptions { alpha, register, geometry } = options;
    let m = fresh.task_dim;
    let (frame, measured) = if register {
        if m != 3 {
            return Err(CheckError::PlanarFrame);
        }
        if fresh.len() < register::FRAME_DOF {
            return Err(CheckError::TooFewRows { rows: fresh.len(), needed: register::FRAME_DOF });
        }
        let (frame, moved) = register::register(&fresh.positions, predicted).ok_or(CheckError::DegenerateFrame)?;
        (Some(frame), moved)
    } else {
        (None, fresh.positions.clone())
    };
    let c = covariance::fresh_covariance(model, fresh, geometry).ok_or(if model.noise_sigma.is_none() {
        CheckError::NoSigma
    } else {
        CheckError::NotPositiveDefinite
    })?;
    let norm = &model.normalisation;
    // The residual in the covariance's internal units (a length: / scale).
    let r: Vec<f64> = measured.iter().zip(predicted).map(|(y, p)| norm.length_to_internal(y - p)).collect();
    let tangent = frame.map(|_| register::tangent(&measured.iter().map(|v| norm.length_to_internal(*v)).collect::<Vec<_>>()));
    let statistic = statistic::mahalanobis(&c, &r, tangent.as_ref()).ok_or(if frame.is_some() && r.len() <= register::FRAME_DOF {
        CheckError::TooFewRows { rows: fresh.len(), needed: register::FRAME_DOF }
    } else {
        CheckError::NotPositiveDefinite
    })?;
    let verdict = if statistic.p_value < alpha { Verdict::Changed } else { Verdict::Holds };
    Ok(Check { statistic, verdict, frame, measured, residual: r, covariance: c, tangent })
}

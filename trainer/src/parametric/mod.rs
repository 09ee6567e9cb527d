//! Parametric (geometric) calibration: Levenberg–Marquardt over every Denavit–Hartenberg parameter
//! (a, α, d, θ_offset of each joint), the base transform (3 translations + 3 small rotations,
//! applied on the left of the nominal base), the tool translation and, when tool points lie off the
//! tool origin, the tool's rotation (at the origin it moves no measured point). A stage of the product: `--dh-first`
//! before CbD, diagnose's geometric group, plan's identifiability.
//!
//! One operation per file: the residuals k(p; x_i) − y_i (`residuals`), their analytic
//! identification Jacobian ∂k/∂p (`jacobian`), the identifiable parameters by column-pivoted QR
//! (`identifiable`), the damped least-squares loop (`least_squares`), the fit itself
//! (`calibrate_dh`) and a tracker frame's base registered and refined by it (`base_registration`).
//!
//! Columns are scaled to unit norm; the damped steps come from the SVD of the scaled Jacobian
//! (`numeric::least_squares::TruncatedSvd`, never JᵀJ itself), and directions whose eigenvalue of
//! the scaled JᵀJ (σ²) is below `rank_tolerance × λ_max` are dropped: unidentifiable combinations
//! (e.g. d₂ + d₃ + d₄ for parallel axes, base yaw vs θ₁ offset) stay at their nominal values (the
//! minimum-norm change in scaled parameters) and are reported by name.

pub mod base_registration;
mod calibrate_dh;
pub mod identifiable;
pub mod jacobian;
pub mod least_squares;
mod linearised;
mod residuals;
#[cfg(test)]
pub(crate) mod tests;

pub use calibrate_dh::calibrate_dh;
pub use identifiable::{identification_jacobian, independent_columns};
pub use jacobian::geometric_jacobian;
pub use linearised::{linearised_group, LinearisedGroup};

use cbd_protocol::NominalModel;

/// Settings of the fit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DhCalibrationOptions {
    pub max_iterations: usize,
    /// Eigenvalues of the scaled JᵀJ below this fraction of the largest are unidentifiable.
    pub rank_tolerance: f64,
    /// Stop when an accepted step lowers the cost by less than this fraction.
    pub cost_tolerance: f64,
    /// Parameters whose (unit-scaled) Jacobian column lies within this distance of the span of
    /// the others at the nominal model are redundant and kept at their nominal values
    /// (column-pivoted QR, [`independent_columns`]). 0 disables.
    pub redundancy_tolerance: f64,
    /// Fit a planar arm as its DH form (the result is then a 3-D DH chain read in its first two
    /// coordinates, which only callers that read it so — compare, diagnose — can use); when
    /// false a planar arm is refused as before.
    pub planar_as_dh: bool,
}

impl Default for DhCalibrationOptions {
    fn default() -> Self {
        DhCalibrationOptions {
            max_iterations: 200,
            rank_tolerance: 1e-14,
            cost_tolerance: 1e-15,
            redundancy_tolerance: 1e-9,
            planar_as_dh: false,
        }
    }
}

/// What the fit did.
#[derive(Debug, Clone, PartialEq)]
pub struct DhFitStats {
    pub iterations: usize,
    /// Root-mean-square position error (Euclidean, per measurement) before and after.
    pub initial_rms: f64,
    pub final_rms: f64,
    pub n_parameters: usize,
    /// Identifiable directions (numerical rank of the scaled Jacobian at the solution).
    pub rank: usize,
    /// For each unidentifiable direction, the parameters that dominate it (weight > 0.3).
    pub unidentifiable: Vec<String>,
    /// Change of every parameter from the nominal (names in `parameter_names`).
    pub parameter_changes: Vec<f64>,
    pub parameter_names: Vec<String>,
    pub converged: bool,
    /// Parameters redundant at the nominal model (first stage kept them fixed).
    pub redundant_at_nominal: Vec<String>,
}

#[derive(Debug, Clone)]
pub struct DhCalibration {
    pub model: NominalModel,
    pub stats: DhFitStats,
}

#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DhCalibrationError {
    /// Only DH chains have DH parameters.
    #[error("DH calibration needs a DH chain as nominal model")]
    NotADhChain,
    /// Fewer measured coordinates than parameters would be meaningless.
    #[error("DH calibration: {rows} measurements are too few")]
    TooFewMeasurements { rows: usize },
    /// The SVD of the Jacobian failed (non-finite data?).
    #[error("DH calibration: {0}")]
    Numerical(#[from] crate::numeric::least_squares::LeastSquaresError),
}

impl From<DhCalibrationError> for crate::Error {
    fn from(e: DhCalibrationError) -> crate::Error {
        crate::Error::stage("DH calibration", e)
    }
}

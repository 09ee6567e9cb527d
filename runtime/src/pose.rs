//! The calibrated tool pose (issue 26 item 1): every tool point's calibrated position and exact
//! Jacobian ([`Calibrator::evaluate_point`]: the same flows carry every point) and the tool frame
//! they imply, the least-squares rigid fit of the nominal offsets onto the calibrated points
//! ([`crate::kinematics::tool_frame`]), with its 6 × n Jacobian (linear velocity of the origin,
//! angular velocity).

use crate::error::Error;
use crate::evaluate::{evaluate_point, Evaluation};
use crate::kinematics::spatial::V3;
use crate::kinematics::tool_frame::{fit_frame, FrameVelocity};
use crate::load::Calibrator;
use cbd_protocol::{MAX_JOINTS as NJ, MAX_TOOL_POINTS};
use nalgebra::{Dyn, MatrixView, SMatrix, U1, U6};

/// The calibrated tool pose at one configuration, in the user's units.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoseEvaluation {
    pub(crate) points: [Option<Evaluation>; MAX_TOOL_POINTS],
    pub(crate) count: usize,
    pub(crate) rotation: [V3; 3],
    pub(crate) origin: V3,
    pub(crate) residual: f64,
    pub(crate) jacobian: SMatrix<f64, 6, NJ>,
    pub(crate) n_joints: usize,
}

impl PoseEvaluation {
    /// m_p, the tool points evaluated.
    pub fn point_count(&self) -> usize {
        self.count
    }
    /// Tool point `j`'s calibrated position and exact Jacobian ([`Calibrator::evaluate_point`]).
    pub fn point(&self, j: usize) -> Option<&Evaluation> {
        self.points.get(j).and_then(Option::as_ref)
    }
    /// R, the calibrated tool frame's rotation in the task frame (rows): the least-squares rotation
    /// of the nominal tool points onto the calibrated ones.
    pub fn rotation(&self) -> [[f64; 3]; 3] {
        self.rotation
    }
    /// The calibrated tool frame's origin (where the fitted frame puts the tool-frame point 0).
    pub fn origin(&self) -> [f64; 3] {
        self.origin
    }
    /// √(Σ_j |R p_j + t − y_j|² / m_p): how far the calibrated points are from a rigid copy of the
    /// nominal ones (the flow deforms them slightly; user units).
    pub fn fit_residual(&self) -> f64 {
        self.residual
    }
    /// The 6 × n Jacobian of the tool frame: rows 0–2 the origin's linear velocity, rows 3–5 the
    /// angular velocity ω (dR = [ω]× R) per unit joint velocity, exact for the fit of the exactly
    /// differentiated calibrated points.
    pub fn jacobian(&self) -> MatrixView<'_, f64, U6, Dyn, U1, U6> {
        self.jacobian.generic_view((0, 0), (U6, Dyn(self.n_joints.min(NJ))))
    }
    /// Kernel support at the configuration ([`Evaluation::support`], the same for every point).
    pub fn support(&self) -> f64 {
        self.point(0).map_or(0.0, Evaluation::support)
    }
}

/// Every tool point's calibrated position and Jacobian at `q` and the calibrated tool frame
/// ([`PoseEvaluation`]). [`Error::OrientationUndetermined`] when the model's tool points do not
/// determine an orientation (fewer than 3, or all on one line): never a guess.
pub fn evaluate_pose(cal: &mut Calibrator<'_>, q: &[f64]) -> Result<PoseEvaluation, Error> {
    let count = cal.model.nominal.tool_point_count();
    let mut nominal = [[0.0; 3]; MAX_TOOL_POINTS];
    for (j, p) in nominal.iter_mut().enumerate().take(count) {
        *p = cal.model.nominal.tool_point(j).ok_or(Error::Internal)?;
    }
    let nominal = nominal.get(..count).ok_or(Error::OrientationUndetermined)?;
    if !crate::kinematics::tool_frame::determines_orientation(nominal) {
        return Err(Error::OrientationUndetermined);
    }
    let mut points: [Option<Evaluation>; MAX_TOOL_POINTS] = [None; MAX_TOOL_POINTS];
    let mut measured = [[0.0; 3]; MAX_TOOL_POINTS];
    for (j, (slot, y)) in points.iter_mut().zip(measured.iter_mut()).enumerate().take(count) {
        let e = evaluate_point(cal, q, j)?;
        for (dst, v) in y.iter_mut().zip(e.position.iter()) {
            *dst = *v;
        }
        *slot = Some(e);
    }
    let measured = measured.get(..count).ok_or(Error::Internal)?;
    let fit = fit_frame(nominal, measured).ok_or(Error::OrientationUndetermined)?;
    let velocity = FrameVelocity::new(&fit, nominal, measured).ok_or(Error::OrientationUndetermined)?;
    let n = cal.dims.n;
    let mut jacobian = SMatrix::<f64, 6, NJ>::zeros();
    for d in 0..n {
        // Column d: every point's velocity along joint d, then the frame's.
        let mut column = [[0.0; 3]; MAX_TOOL_POINTS];
        for (dy, e) in column.iter_mut().zip(points.iter()).take(count) {
            let e = e.as_ref().ok_or(Error::Internal)?;
            for (a, v) in dy.iter_mut().enumerate() {
                *v = e.jacobian.get((a, d)).copied().ok_or(Error::Internal)?;
            }
        }
        let (dt, omega) = velocity.apply(column.get(..count).ok_or(Error::Internal)?).ok_or(Error::Internal)?;
        for (a, v) in dt.iter().chain(omega.iter()).enumerate() {
            if let Some(dst) = jacobian.get_mut((a, d)) {
                *dst = *v;
            }
        }
    }
    if !jacobian.as_slice().iter().all(|v| v.is_finite()) {
        return Err(Error::NonFiniteResult);
    }
    Ok(PoseEvaluation { points, count, rotation: fit.rotation, origin: fit.origin, residual: fit.residual, jacobian, n_joints: n })
}

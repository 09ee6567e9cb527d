//! The controller's API: [`Calibrator`]'s methods, each a thin wrapper over the function of the
//! module that owns the operation (pinocchio's style, `algorithm(calibrator, q)`): loading
//! ([`crate::load`]), evaluation ([`crate::evaluate`], [`crate::pose`]), the flows as maps
//! ([`crate::flow_maps`]) and compensation ([`crate::compensate`], [`crate::compensate_pose`]).

use crate::compensate::{self, CompensateOptions, Compensation};
use crate::compensate_pose::{self, PoseCompensateOptions, PoseCompensation};
use crate::error::Error;
use crate::evaluate::{self, Evaluation};
use crate::flow::inverse::Direction;
use crate::flow_maps;
use crate::load;
use crate::load::Calibrator;
use crate::pose::{self, PoseEvaluation};
use crate::real::Real;
use cbd_protocol::Model;

impl<'a> Calibrator<'a> {
    /// Decodes and validates `blob`, then integrates the control points' trajectories into `storage`
    /// (with an expansion: copies its weights), which must hold at least [`crate::storage_len_for`] values.
    pub fn load(blob: &'a [u8], storage: &'a mut [Real]) -> Result<Self, Error> {
        load::load(blob, storage)
    }

    /// As [`Calibrator::load`], for a model already decoded.
    pub fn from_model(model: Model<'a>, storage: &'a mut [Real]) -> Result<Self, Error> {
        load::from_model(model, storage)
    }

    /// The model this calibrator evaluates.
    pub fn model(&self) -> &Model<'a> {
        &self.model
    }

    /// A bound on how far rounding alone moves one evaluated position, user units
    /// ([`crate::precision::evaluation_precision`]): what this model, in this build's scalar, can resolve.
    pub fn precision(&self) -> f64 {
        self.precision
    }

    /// k1(ξ) and its exact Jacobian Dk1(ξ) at `q`, tool point 0 ([`evaluate::evaluate`]).
    pub fn evaluate(&mut self, q: &[f64]) -> Result<Evaluation, Error> {
        evaluate::evaluate(self, q)
    }

    /// k1(ξ) and its exact Jacobian for tool point `j` ([`evaluate::evaluate_point`]).
    pub fn evaluate_point(&mut self, q: &[f64], j: usize) -> Result<Evaluation, Error> {
        evaluate::evaluate_point(self, q, j)
    }

    /// k1(ξ) and the transported J(1) of eq. (19), without tangents ([`evaluate::evaluate_transported`]).
    pub fn evaluate_transported(&mut self, q: &[f64]) -> Result<Evaluation, Error> {
        evaluate::evaluate_transported(self, q)
    }

    /// Every tool point's calibrated position and Jacobian at `q` and the calibrated tool frame
    /// ([`pose::evaluate_pose`]).
    pub fn evaluate_pose(&mut self, q: &[f64]) -> Result<PoseEvaluation, Error> {
        pose::evaluate_pose(self, q)
    }

    /// ψ(y) (forward) or ψ⁻¹(y) (backward) ([`flow_maps::task_flow`]).
    pub fn task_flow(&self, y: &[f64], direction: Direction, out: &mut [f64]) -> Result<(), Error> {
        flow_maps::task_flow(self, y, direction, out)
    }

    /// φ(x) (forward) or φ⁻¹(x) (backward) ([`flow_maps::joint_flow`]).
    pub fn joint_flow(&mut self, x: &[f64], direction: Direction, out: &mut [f64]) -> Result<(), Error> {
        flow_maps::joint_flow(self, x, direction, out)
    }

    /// k1⁻¹ = φ ∘ k0⁻¹ ∘ ψ⁻¹, the start of compensation ([`flow_maps::inverse_flow_start`]).
    pub fn inverse_flow_start(&mut self, target: &[f64], seed: &[f64], out: &mut [f64], nominal_iterations: usize) -> Result<(), Error> {
        flow_maps::inverse_flow_start(self, target, seed, out, nominal_iterations)
    }

    /// [`Calibrator::compensate_with`] with [`CompensateOptions::for_model`].
    pub fn compensate(&mut self, target: &[f64], seed: &[f64], out: &mut [f64]) -> Result<Compensation, Error> {
        compensate::compensate(self, target, seed, out)
    }

    /// The joint command q with k1(q) = `target`, by damped minimum-norm Gauss–Newton steps from the
    /// inverse flows' start ([`compensate::compensate_with`]).
    pub fn compensate_with(
        &mut self,
        target: &[f64],
        seed: &[f64],
        out: &mut [f64],
        options: &CompensateOptions,
    ) -> Result<Compensation, Error> {
        compensate::compensate_with(self, target, seed, out, options)
    }

    /// [`Calibrator::compensate_pose_with`] with [`PoseCompensateOptions::for_model`].
    pub fn compensate_pose(
        &mut self,
        position: &[f64],
        rotation: &[[f64; 3]; 3],
        seed: &[f64],
        out: &mut [f64],
    ) -> Result<PoseCompensation, Error> {
        compensate_pose::compensate_pose(self, position, rotation, seed, out)
    }

    /// The joint command q whose calibrated tool frame has origin `position` and rotation
    /// `rotation` ([`compensate_pose::compensate_pose_with`]).
    pub fn compensate_pose_with(
        &mut self,
        position: &[f64],
        rotation: &[[f64; 3]; 3],
        seed: &[f64],
        out: &mut [f64],
        options: &PoseCompensateOptions,
    ) -> Result<PoseCompensation, Error> {
        compensate_pose::compensate_pose_with(self, position, rotation, seed, out, options)
    }
}

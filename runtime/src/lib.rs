//! Evaluates a calibrated model k1 = ψ ∘ k0 ∘ φ⁻¹ (Calibration by Diffeomorphisms) on a
//! controller: `#![no_std]`, no heap, fixed-step integration of eq. (20), position and Jacobian.
//!
//! ```ignore
//! let mut storage = [0.0; 200_000]; // Real values (f64, or f32 with the `f32` feature), ≥ storage_len_for(&model)
//! let mut cal = Calibrator::load(BLOB, &mut storage)?;
//! let e = cal.evaluate(&[0.3, -1.2])?;
//! let (y, dy) = (e.position(), e.jacobian());
//! ```
//!
//! The controller's API is at the crate root: [`Calibrator`] (load, `evaluate`, `compensate`; with
//! several tool points per pose `evaluate_point`, `evaluate_pose`, `compensate_pose`),
//! [`Evaluation`], [`PoseEvaluation`], [`storage_len_for`] (and the kernel form's [`storage_len`]), [`Error`].
//! `Calibrator`'s methods (`calibrator`) wrap the functions of the modules that own the operations
//! (`load`, `evaluate`, `pose`, `flow_maps`, `compensate`, `compensate_pose`), each taking the loaded
//! model first, pinocchio's `algorithm(model, data, q)`. The modules below them are the building
//! blocks the trainer shares so that it optimises exactly what the controller evaluates (same code,
//! same bits): `kinematics` (k0 and its derivatives), `kernel`, `flow` (eq. 17, 19, 20, the control
//! points' integration, the query's derivatives, the inverse flows' pieces), `expansion` (format 5:
//! the fields in their kernels' own basis, evaluated instead of the kernel form when the blob has
//! them), `integrate`, `real`, and `inverse_kinematics` (the nominal closed forms compensation starts
//! from). docs/DESIGN.md §1 lists the layers; no module imports from a layer above its own.
#![no_std]
#![deny(missing_docs)]
#![cfg_attr(not(test), deny(clippy::unwrap_used, clippy::expect_used, clippy::panic, clippy::indexing_slicing))]
// `!(a >= b)` is how this crate writes "a < b, or NaN": a non-finite value takes the refusing branch.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod calibrator;
pub mod compensate;
pub mod compensate_pose;
pub mod error;
pub mod evaluate;
pub mod expansion;
pub mod flow;
pub mod flow_maps;
pub mod integrate;
pub mod inverse_kinematics;
pub mod kernel;
pub mod kinematics;
pub mod load;
pub mod pose;
pub mod precision;
pub mod real;

pub use cbd_protocol as protocol;
pub use compensate::{CompensateOptions, Compensation};
pub use compensate_pose::{PoseCompensateOptions, PoseCompensation};
pub use error::Error;
pub use evaluate::Evaluation;
pub use load::{storage_len, storage_len_for, Calibrator};
pub use pose::PoseEvaluation;

//! Offline trainer for Calibration by Diffeomorphisms, laid out by pipeline stage, bottom to top
//! (docs/DESIGN.md §1 states the layers; `cargo test -p cbd-tests --test cross_crate house::` checks them):
//! errors, files and the bound on imported values → worker threads and numerical building blocks
//! (least squares, the Levenberg–Marquardt driver) → nominal models and memory → data import →
//! simulation, flow (primal + tangent), reports → the kernels' expansions, the solver, parametric (DH)
//! calibration → CbD's evidence → calibrate (the one pipeline) → diagnosis, planning, evaluation
//! harnesses → the peers (kernel ridge) → the library's face (`face`: a calibration's operations on
//! parsed values) → the `cbd` CLI.

/// `eprintln!` that never panics: a line to a closed or broken stderr (`cbd … 2>&1 | head -1`) is
/// dropped, as `cli::print_line` ends quietly on a closed stdout. Every diagnostic of the crate and
/// the binary goes through it (or to the program's sink: `io::set_message_sink`).
#[macro_export]
macro_rules! errln {
    ($($t:tt)*) => {{
        use std::io::Write as _;
        if !$crate::io::to_sink($crate::io::Stream::Err, format_args!($($t)*)) {
            let _ = writeln!(std::io::stderr(), $($t)*);
        }
    }};
}

/// The joint kernel's axis forms: one descriptor per form (docs/DESIGN.md §4).
pub mod axis_forms;
/// The peers CbD is compared with (kernel ridge on the residual).
pub mod baselines;
/// The one calibration pipeline: hyperparameters, scheme, fit, blob.
pub mod calibrate;
/// The `cbd` command line.
pub mod cli;
/// Measurement import: CSV, model files, units, joint maps.
pub mod data;
/// Residual diagnosis: which physical effects the data show.
pub mod diagnose;
/// One descriptor per physical effect kind: file entry, simulator, library, labels (docs/DESIGN.md §7).
pub mod effects;
/// The trainer's one error type (every stage's error enters it as a source).
pub mod error;
/// Evaluation harnesses: side-by-side comparison and commanded accuracy, any fitter through a hook.
pub mod evaluation;
/// CbD's own evidence: hyperparameters by marginal likelihood (docs/DESIGN.md §3, §9).
pub mod evidence;
/// The fields in the kernels' own basis (docs/DESIGN.md §11).
pub mod expansion;
/// The library's face: fit, and what a front needs around it, on parsed values (issue 52).
pub mod face;
/// The control points' flow and its tangent (eq. 17, 19).
pub mod flow;
/// Reading inputs and writing outputs safely (atomic writes, no writes through links).
pub mod io;
/// The bound every imported value obeys.
pub mod limits;
/// What a fit needs in memory, checked before it allocates, and the worker threads it runs on.
pub mod memory;
/// Nominal models: DH chains, planar arms, URDF, rigid fits, batched k0.
pub mod nominal;
/// Numerical building blocks: linear least squares, the Levenberg–Marquardt driver, faer's split.
pub mod numeric;
/// Parametric (DH / geometric) calibration: its Jacobian, identifiable set and least squares.
pub mod parametric;
/// Where to measure next (docs/DESIGN.md §13).
pub mod plan;
/// Evaluating a trained blob with the runtime.
pub mod predict;
/// Figures, statistics, progress and the HTML report.
pub mod report;
/// Simulated arms: the paper's RR, a six-joint arm, injected physical effects.
pub mod simulate;
/// Energy (16) minimised over the momenta: closed form and Levenberg–Marquardt (`numeric`'s driver).
pub mod solver;

pub use error::{Error, Result};

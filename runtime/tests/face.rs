//! The controller's face (issue 52): the crate root's public names, pinned. Adding, removing or
//! renaming one fails here first, so a change of the API firmware builds against is a visible diff
//! of this file. The signatures are pinned by naming each item with its type.

use cbd_runtime::{
    storage_len, storage_len_for, Calibrator, CompensateOptions, Compensation, Error, Evaluation, PoseCompensateOptions, PoseCompensation,
    PoseEvaluation, Real, MAX_JOINTS, MAX_TASK_DIM,
};

/// Every `pub` line at the root of src/lib.rs (outside `internals`), as written.
const FACE: &[&str] = &[
    "pub use cbd_protocol::{MAX_JOINTS, MAX_TASK_DIM};",
    "pub use compensate::{CompensateOptions, Compensation};",
    "pub use compensate_pose::{PoseCompensateOptions, PoseCompensation};",
    "pub use error::Error;",
    "pub use evaluate::Evaluation;",
    "pub use load::{storage_len, storage_len_for, Calibrator};",
    "pub use pose::PoseEvaluation;",
    "pub use real::Real;",
    "pub mod internals {",
];

#[test]
fn the_root_exports_the_face_and_one_module_of_internals() {
    let lib = include_str!("../src/lib.rs");
    assert!(lib.lines().any(|l| l == "#![no_std]"), "the runtime must stay #![no_std]");
    let root: Vec<&str> = lib.lines().filter(|l| l.starts_with("pub ")).collect();
    assert_eq!(root, FACE, "the runtime's face changed: update FACE (and the firmware docs) deliberately");
    let names: usize = FACE.iter().map(|l| if l.contains('{') && l.contains('}') { l.matches(',').count() + 1 } else { 1 }).sum();
    assert!(names <= 15, "{names} names at the root (issue 52: at most 15)");
    assert_eq!(root.iter().filter(|l| l.starts_with("pub mod")).count(), 1);
    assert!(!lib.lines().any(|l| l.starts_with("pub(crate) mod") || l.starts_with("pub mod ") && !l.starts_with("pub mod internals")));
}

#[test]
fn the_faces_signatures() {
    let _: fn(&cbd_protocol::Model<'_>) -> usize = storage_len_for;
    let _: fn(usize, usize, usize, cbd_protocol::Integrator) -> usize = storage_len;
    // Methods through closures: the impl's lifetime is early-bound, so no fn pointer names them.
    let _ = |blob: &'static [u8], storage: &'static mut [Real]| -> Result<Calibrator<'static>, Error> { Calibrator::load(blob, storage) };
    let _ = |c: &mut Calibrator<'_>, q: &[f64]| -> Result<Evaluation, Error> { c.evaluate(q) };
    let _ = |c: &mut Calibrator<'_>, q: &[f64]| -> Result<PoseEvaluation, Error> { c.evaluate_pose(q) };
    let _ = |c: &mut Calibrator<'_>, target: &[f64], seed: &[f64], out: &mut [f64]| -> Result<Compensation, Error> {
        c.compensate(target, seed, out)
    };
    let _ = |c: &Calibrator<'_>| -> (CompensateOptions, PoseCompensateOptions) {
        (CompensateOptions::for_model(c), PoseCompensateOptions::for_model(c))
    };
    let _: Option<PoseCompensation> = None;
    assert!(MAX_JOINTS >= 6 && MAX_TASK_DIM >= 3);
}

//! Cross-crate tests (trainer → blob → runtime), one module per subject.
//!
//! One test binary, not one per file: it links once and its tests share the cores. One subject:
//! `cargo test --release -p cbd-tests --test cross_crate compensate::`.

mod blob_integrity;
mod compensate;
mod determinism;
mod effects;
mod exact_jacobian;
mod expansion;
mod expansion_fit;
mod finite_differences;
mod house;
mod inverse_flow;
mod reference_flow;
mod round_trip;
mod runtime_robustness;
mod tool_points;

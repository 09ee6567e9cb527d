//! The trainer's tests from outside: the `cbd` binary and the library face, one module per subject.
//!
//! One test binary, not one per file: it links once (a rebuild after the test sources changed took
//! 229 s with 46 release links of the trainer, 19 s with two) and its tests share the cores. One subject:
//! `cargo test --release -p cbd-trainer --test end_to_end drift::`.

mod cli_support;
mod common;

// The firmware check's blob builders, compiled here exactly as `cbd-fw-host` compiles them (for
// blob_hashes; at the root because they name `crate::shared`).
#[path = "../../../examples/fw-host/src/blobs.rs"]
#[allow(dead_code)]
mod blobs;
#[path = "../../../examples/firmware/src/shared.rs"]
#[allow(dead_code)]
mod shared;

mod blob_hashes;
mod cli_check;
mod cli_contract_properties;
mod cli_errors;
mod cli_properties;
mod cli_reliability;
mod cli_reliability_iv;
mod cli_reliability_v;
mod diagnose;
mod diagnose_sweep;
mod diagnose_tool_points;
mod docs;
mod docs_commands;
mod drift;
mod eigenspace_optimality;
mod evidence_basins;
mod export;
mod gemm_workspace;
mod geometry_choice;
mod joint_map;
mod large_cache_host;
mod long_chain;
mod model_parsed_once;
mod pipeline;
mod plan_cli;
mod planar_frame;
mod six_joint_generalisation;
mod tool_points;
mod tracker_frame;
mod ur5_example;

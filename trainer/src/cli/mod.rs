//! The `cbd` command line: one file per command.

/// `println!` for the CLI's stdout: through [`print_line`], so that a reader that went away
/// (`cbd eval ... | head -1`) ends the process quietly instead of a panic.
macro_rules! outln {
    () => {
        $crate::cli::print_line(format_args!(""))
    };
    ($($t:tt)*) => {
        $crate::cli::print_line(format_args!($($t)*))
    };
}

pub mod args;
pub mod bench;
pub mod blob_rows;
pub mod check;
pub mod compare;
pub mod compensate;
pub mod demo;
pub mod diagnose;
pub mod eval;
pub mod export;
pub mod fit;
pub mod plan;
pub mod report;
pub mod simulate;

pub use args::ModelArgs;

use crate::error::Result;
use clap::{Parser, Subcommand};

#[derive(Debug, Parser)]
#[command(name = "cbd", version, about = "Calibration by Diffeomorphisms: train, evaluate and compare calibrated robot models")]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Debug, Subcommand)]
pub enum Command {
    /// The paper's RR benchmark end to end, on built-in defaults.
    Demo(demo::DemoArgs),
    /// Simulate measurements of a robot with known errors, as CSV.
    Simulate(simulate::SimulateArgs),
    /// Train a calibrated model blob from measurements.
    Fit(fit::FitArgs),
    /// Evaluate a blob on measurements: mean, median, p99 and max position error.
    Eval(eval::EvalArgs),
    /// Does the calibration still hold? Fresh poses tested against the blob's own predictive
    /// distribution: exit 0 when it holds, 3 when it changed.
    Check(check::CheckArgs),
    /// One self-contained HTML page for a run: inputs, hyperparameters, convergence, error tables, figures.
    Report(report::ReportArgs),
    /// All peers side by side on the same data: nominal, DH, kernel ridge, CbD and hybrids.
    Compare(compare::CompareArgs),
    /// Fit time, memory and evaluation time against N (writes BENCHMARKS.md with --markdown).
    Bench(bench::BenchArgs),
    /// Joint commands that put the calibrated arm's tool at Cartesian targets (calibrated inverse kinematics).
    Compensate(compensate::CompensateArgs),
    /// Trace the residual to physical effects (library fit, out-of-sample selection) and report before/after.
    Diagnose(diagnose::DiagnoseArgs),
    /// The calibrated geometry for ROS: a URDF (joint origins calibrated) and the UR description's kinematics file.
    Export(export::ExportArgs),
    /// Where to measure next: poses within the joint limits chosen for identifiability and CbD's
    /// posterior variance, with the predicted RMS error after each (learning curve).
    Plan(plan::PlanArgs),
}

/// Chooses how glibc malloc keeps freed memory for this process (`crate::solver::allocator`):
/// returned at once under an address-space limit (`ulimit -v`), where kept memory would run out
/// after the memory check let a fit start; kept otherwise (faster fits). A process-wide setting:
/// the `cbd` binary calls it first thing, before any allocation of size; a program using the
/// library decides for itself (the library never changes it behind the caller's back).
pub fn configure_allocator() {
    if memory::address_space_limited() {
        crate::solver::allocator::track_live_memory();
    } else {
        crate::solver::allocator::keep_freed_memory();
    }
}

/// Runs a parsed command as every front does (`crate::face::run`: worker pool, staged outputs);
/// errors are printed by `main` with exit code 1.
pub fn run(cli: Cli) -> Result<()> {
    crate::face::run(move || command(cli))
}

fn command(cli: Cli) -> Result<()> {
    match cli.command {
        Command::Demo(args) => demo::run(args),
        Command::Simulate(args) => simulate::run(args),
        Command::Fit(args) => fit::run(args),
        Command::Eval(args) => eval::run(args),
        Command::Check(args) => check::run(args),
        Command::Bench(args) => bench::run(args),
        Command::Compare(args) => compare::run(args),
        Command::Report(args) => report::run(args),
        Command::Diagnose(args) => diagnose::run(args),
        Command::Compensate(args) => compensate::run(args),
        Command::Plan(args) => plan::run(args),
        Command::Export(args) => export::run(args),
    }
}

/// The exit code of a command that succeeded: 0, or 3 from `cbd check` when the calibration changed
/// (docs/EXIT_CODES.md). `main` exits with it after the outputs are in place.
static EXIT_CODE: std::sync::atomic::AtomicI32 = std::sync::atomic::AtomicI32::new(0);

/// Sets the exit code of a successful command ([`exit_code`]).
pub fn set_exit_code(code: i32) {
    EXIT_CODE.store(code, std::sync::atomic::Ordering::SeqCst);
}

/// The exit code the command that succeeded asked for (0 unless it set one).
pub fn exit_code() -> i32 {
    EXIT_CODE.load(std::sync::atomic::Ordering::SeqCst)
}

// Output files (atomic writes, `-` for standard output) live in `crate::io`, the memory estimates
// in `crate::memory`, the arm a command works on in `crate::face`; the commands reach them here.
pub use crate::face::ArmModel;
pub use crate::io::{check_output, is_stdout, write_atomically, STDOUT};
pub use crate::memory;

/// Writes one line to stdout (locked, flushed as `println!` does). A closed pipe (EPIPE: the reader
/// took what it wanted, `| head -1`) is a quiet, successful exit — what the default SIGPIPE does for
/// C tools, without Rust's `println!` panic; any other write error is an error line and exit code 1.
/// A program's message sink (`io::set_message_sink`) takes the line instead.
pub fn print_line(args: std::fmt::Arguments<'_>) {
    use std::io::Write;
    if crate::io::to_sink(crate::io::Stream::Out, args) {
        return;
    }
    let mut out = std::io::stdout().lock();
    match writeln!(out, "{args}").and_then(|_| out.flush()) {
        Ok(()) => {}
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => std::process::exit(0),
        Err(e) => {
            errln!("error: writing to stdout: {e}");
            std::process::exit(1)
        }
    }
}

/// The commands' arguments read from keywords (serde: the Python package) and from the command
/// line (clap) agree: one set of defaults, unknown names refused.
#[cfg(test)]
mod settings_tests {
    use super::*;
    use clap::Parser;

    fn parsed(args: &[&str]) -> Command {
        Cli::try_parse_from(std::iter::once("cbd").chain(args.iter().copied())).unwrap().command
    }

    fn keywords<T: serde::de::DeserializeOwned>(value: serde_json::Value) -> std::result::Result<T, String> {
        serde_json::from_value(value).map_err(|e| e.to_string())
    }

    #[test]
    fn keyword_defaults_are_the_flags_defaults() {
        use serde_json::json;
        let Command::Fit(flags) = parsed(&["fit", "--data", "d.csv", "--out", "o.blob"]) else { unreachable!() };
        let named: crate::face::FitSettings = keywords(json!({})).unwrap();
        assert_eq!(format!("{:?}", flags.settings), format!("{named:?}"));
        let Command::Compare(flags) = parsed(&["compare", "--model", "m.toml", "--train", "a.csv", "--test", "b.csv"]) else {
            unreachable!()
        };
        let named: crate::face::CompareSettings = keywords(json!({})).unwrap();
        assert_eq!(format!("{:?}", flags.settings), format!("{named:?}"));
        let Command::Diagnose(flags) = parsed(&["diagnose", "--data", "d.csv"]) else { unreachable!() };
        let named: crate::face::DiagnoseSettings = keywords(json!({})).unwrap();
        assert_eq!(format!("{:?}", flags.settings), format!("{named:?}"));
        let Command::Simulate(flags) = parsed(&["simulate", "--out", "s.csv"]) else { unreachable!() };
        let named: crate::face::SimulateSettings = keywords(json!({})).unwrap();
        assert_eq!(format!("{:?}", flags.settings), format!("{named:?}"));
    }

    #[test]
    fn keywords_are_the_flags_values() {
        use serde_json::json;
        let Command::Fit(flags) = parsed(&[
            "fit",
            "--data",
            "d.csv",
            "--out",
            "o.blob",
            "--model",
            "m.toml",
            "--dh-first",
            "--max-rows",
            "500",
            "--sigma",
            "0.001",
            "--configuration-field",
            "off",
            "--representation",
            "kernel",
            "--quiet",
        ]) else {
            unreachable!()
        };
        let named: crate::face::FitSettings = keywords(json!({
            "dh_first": true, "max_rows": 500, "sigma": 1e-3, "configuration_field": "off", "representation": "kernel", "quiet": true,
        }))
        .unwrap();
        assert_eq!(format!("{:?}", flags.settings), format!("{named:?}"));
        let Command::Simulate(flags) = parsed(&["simulate", "--out", "s.csv", "--effect", "backlash", "--robot", "six"]) else {
            unreachable!()
        };
        let named: crate::face::SimulateSettings = keywords(json!({"effect": "backlash", "robot": "six"})).unwrap();
        assert_eq!(format!("{:?}", flags.settings), format!("{named:?}"));
        let named: crate::face::SimulateSettings = keywords(json!({"effect": ["backlash"], "robot": "six"})).unwrap();
        assert_eq!(format!("{:?}", flags.settings), format!("{named:?}"));
    }

    #[test]
    fn unknown_or_mistyped_keywords_are_refused() {
        use serde_json::json;
        let e = keywords::<crate::face::FitSettings>(json!({"max_rowz": 3})).unwrap_err();
        assert!(e.contains("max_rowz"), "{e}");
        let e = keywords::<crate::face::DiagnoseSettings>(json!({"harmonic": 3})).unwrap_err();
        assert!(e.contains("harmonic"), "{e}");
        let e = keywords::<crate::face::SimulateSettings>(json!({"out_dir": "x"})).unwrap_err();
        assert!(e.contains("out_dir"), "{e}");
        assert!(keywords::<crate::face::FitSettings>(json!({"max_rows": "many"})).is_err());
        assert!(keywords::<crate::face::FitSettings>(json!({"sigma": "small"})).is_err());
    }
}

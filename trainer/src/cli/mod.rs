//! The `cbd` command line: one file per command.

pub mod bench;
pub mod compare;
pub mod compensate;
pub mod demo;
pub mod diagnose;
pub mod eval;
pub mod fit;
pub mod memory;
pub mod report;
pub mod simulate;

use clap::{Parser, Subcommand};
use std::path::Path;

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
}

/// The nominal model: a model file, or the built-in planar RR arm.
#[derive(Debug, Clone, clap::Args)]
pub struct ModelArgs {
    /// Model file (TOML: DH table or URDF, units, CSV columns). Without it: the paper's RR arm,
    /// CSV columns q1, q2 (radians), x, y.
    #[arg(long)]
    pub model: Option<std::path::PathBuf>,
}

/// The nominal model and how to read its measurement CSV files.
pub fn load_nominal(args: &ModelArgs) -> Result<(cbd_protocol::NominalModel, crate::data::csv_import::ColumnSpec), String> {
    use crate::data::model_file::{AngleUnit, LengthUnit};
    match &args.model {
        Some(path) => {
            let file = crate::data::model_file::load_model_file(path).map_err(|e| e.to_string())?;
            let spec = file.column_spec().map_err(|e| e.to_string())?;
            Ok((file.nominal, spec))
        }
        None => Ok((
            crate::simulate::rr::nominal(),
            crate::data::csv_import::ColumnSpec {
                joint_columns: vec!["q1".into(), "q2".into()],
                position_columns: vec!["x".into(), "y".into()],
                joint_kinds: vec![cbd_protocol::JointKind::Revolute; 2],
                angle_unit: AngleUnit::Rad,
                length_unit: LengthUnit::M,
                model_length_unit: LengthUnit::M,
                min_rows: 2,
                joint_limits: crate::data::csv_import::default_joint_limits(&[cbd_protocol::JointKind::Revolute; 2]),
                repeat_tolerance: None,
            },
        )),
    }
}

/// Runs a parsed command; errors are printed by `main` with exit code 1.
pub fn run(cli: Cli) -> Result<(), String> {
    match cli.command {
        Command::Demo(args) => demo::run(args),
        Command::Simulate(args) => simulate::run(args),
        Command::Fit(args) => fit::run(args),
        Command::Eval(args) => eval::run(args),
        Command::Bench(args) => bench::run(args),
        Command::Compare(args) => compare::run(args),
        Command::Report(args) => report::run(args),
        Command::Diagnose(args) => diagnose::run(args),
        Command::Compensate(args) => compensate::run(args),
    }
}

/// The output path that means standard output.
pub const STDOUT: &str = "-";

/// True for `--out -`: write to standard output instead of a file.
pub fn is_stdout(path: &Path) -> bool {
    path.as_os_str() == STDOUT
}

/// Writes `bytes` to a new temporary file beside `path`, syncs it, then renames it over `path`,
/// so an interrupted write never leaves a truncated file at `path`. Errors name `path`. The rename
/// would replace whatever is at `path` (a symlink, a FIFO, a device node), so only a regular file
/// or a new path is accepted; `-` writes to standard output.
pub fn write_atomically(path: &Path, bytes: &[u8]) -> Result<(), String> {
    use std::io::Write;
    use std::sync::atomic::{AtomicU64, Ordering};
    static COUNTER: AtomicU64 = AtomicU64::new(0);
    if is_stdout(path) {
        let mut out = std::io::stdout().lock();
        return out.write_all(bytes).and_then(|()| out.flush()).map_err(|e| format!("standard output: {e}"));
    }
    check_existing_output(path)?;
    let dir = output_dir(path);
    let name = path.file_name().ok_or_else(|| format!("{}: not a file path", path.display()))?;
    let unique = COUNTER.fetch_add(1, Ordering::Relaxed);
    let tmp = dir.join(format!(".{}.tmp{}-{unique}", name.to_string_lossy(), std::process::id()));
    let written = std::fs::File::create_new(&tmp).and_then(|mut f| {
        f.write_all(bytes)?;
        f.sync_all()
    });
    let result = written.and_then(|()| std::fs::rename(&tmp, path));
    match result {
        Ok(()) => {
            // Make the rename itself durable where the platform allows.
            if let Ok(d) = std::fs::File::open(dir) {
                let _ = d.sync_all();
            }
            Ok(())
        }
        Err(e) => {
            let _ = std::fs::remove_file(&tmp);
            Err(format!("{}: {e}", path.display()))
        }
    }
}

/// The directory an output file goes into.
fn output_dir(path: &Path) -> &Path {
    path.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."))
}

/// What is already at an output path must be a regular file (replaced) or nothing: the atomic
/// rename would silently turn a symlink, FIFO or device node (`/dev/full`) into a regular file.
fn check_existing_output(path: &Path) -> Result<(), String> {
    let meta = match std::fs::symlink_metadata(path) {
        Ok(meta) => meta,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(()),
        Err(e) => return Err(format!("{}: {e}", path.display())),
    };
    let kind = meta.file_type();
    let what = if kind.is_file() {
        return Ok(());
    } else if kind.is_symlink() {
        "a symbolic link"
    } else if kind.is_dir() {
        "a directory"
    } else {
        special_file_kind(&kind)
    };
    Err(format!(
        "{}: is {what}; outputs are written only to regular files or new paths (give a file path, or `-` for standard output)",
        path.display()
    ))
}

#[cfg(unix)]
fn special_file_kind(kind: &std::fs::FileType) -> &'static str {
    use std::os::unix::fs::FileTypeExt;
    if kind.is_fifo() {
        "a FIFO"
    } else if kind.is_char_device() || kind.is_block_device() {
        "a device node"
    } else if kind.is_socket() {
        "a socket"
    } else {
        "not a regular file"
    }
}

#[cfg(not(unix))]
fn special_file_kind(_: &std::fs::FileType) -> &'static str {
    "not a regular file"
}

/// Fails early, before a long computation, if `path` could not be written at the end: its
/// directory is missing or not writable (a probe file is created and removed there), or something
/// other than a regular file is at `path`. `-` (standard output) always passes.
pub fn check_output(path: &Path) -> Result<(), String> {
    if is_stdout(path) {
        return Ok(());
    }
    let dir = output_dir(path);
    if !dir.is_dir() {
        return Err(format!("{}: the directory {} does not exist", path.display(), dir.display()));
    }
    check_existing_output(path)?;
    let probe = dir.join(format!(".cbd-write-probe-{}", std::process::id()));
    match std::fs::File::create_new(&probe) {
        Ok(_) => {
            let _ = std::fs::remove_file(&probe);
            Ok(())
        }
        Err(e) => Err(format!("{}: the directory {} is not writable: {e}", path.display(), dir.display())),
    }
}

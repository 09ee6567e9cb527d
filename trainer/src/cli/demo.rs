//! `cbd demo`: the paper's RR benchmark end to end — simulate, fit, write the blob, load it
//! with the runtime, evaluate on random configurations, compare with kernel ridge regression.

use crate::baselines::kernel_ridge::fit_kernel_ridge_peer;
use crate::cli::memory::MemoryError;
use crate::error::{Context, Error, Result};
use crate::report::stats::ErrorStats;
use crate::simulate::{configurations, rr, Sampling};

use serde::Serialize;
use std::path::PathBuf;

#[derive(Debug, clap::Args)]
pub struct DemoArgs {
    /// Where to write the calibrated model.
    #[arg(long, default_value = "rr-demo.blob")]
    pub out: PathBuf,
    /// Write the figures as JSON here.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Random test configurations.
    #[arg(long, default_value_t = 3000)]
    pub test_points: usize,
    /// Grid points per joint (the paper: 16, i.e. 256 measurements).
    #[arg(long, default_value_t = 16)]
    pub grid: usize,
    /// Write figures (PNG and SVG) into this directory.
    #[arg(long)]
    pub plots: Option<PathBuf>,
    /// `evidence` (CbD's own marginal likelihood and a cross-validated scheme, as `cbd fit` does)
    /// or `paper` (the paper's RR kernels and σ = 1e-6, Euler × 2 unless --steps: the reproduction).
    #[arg(long, default_value = "evidence")]
    pub hyperparameters: String,
    #[command(flatten)]
    pub solver: crate::face::PipelineOptions,
}

#[derive(Debug, Serialize)]
pub struct DemoReport {
    pub nominal: ErrorStats,
    pub calibrated: ErrorStats,
    pub krr: ErrorStats,
    pub nominal_grid: ErrorStats,
    pub calibrated_grid: ErrorStats,
    pub krr_grid: ErrorStats,
    pub fit_seconds: f64,
    pub krr_fit_seconds: f64,
    pub iterations: usize,
    pub blob_bytes: usize,
    pub max_runtime_trainer_diff: f64,
    pub n_train: usize,
    pub n_test: usize,
    pub integrator: String,
    pub steps: u16,
    /// Noise level σ of the fit, length units (the hyperparameters' σ).
    pub sigma: f64,
    /// CbD's evidence search (0 with the paper's hyperparameters); not in `fit_seconds`.
    pub selection_seconds: f64,
    /// What the pipeline chose: hyperparameters, evidence, scheme, warnings.
    pub calibration: serde_json::Value,
    pub fit: crate::solver::FitReport,
}

/// Bytes a demo holds per test point: its joints, measured, nominal, calibrated and kernel ridge
/// positions and their errors, with room for the temporaries.
const BYTES_PER_TEST_POINT: f64 = 16.0 * 8.0;

/// The workers the demo fits on, or why its grid or test points do not fit in `available` bytes.
/// The kernel form (the paper's hyperparameters keep it) is checked up front; the expansion's
/// fits check their workers here and the kernel form against the budget in the solver, as `cbd fit`.
fn check_demo_memory(args: &DemoArgs, settings: &crate::calibrate::Settings, available: Option<f64>) -> Result<usize> {
    use crate::calibrate::HyperparameterSource;
    use crate::cli::memory::{fixed_fit_bytes, gigabytes as gb, CacheSizes};
    use crate::expansion::Representation;
    let flag = format!("--grid {}", args.grid);
    let rows = args.grid.checked_mul(args.grid).ok_or_else(|| MemoryError("too many rows".into())).context(&flag)?;
    let kernel = settings.solver.representation == Representation::Kernel
        || (settings.source == HyperparameterSource::PaperRr && settings.solver.representation == Representation::Auto);
    // Kernel ridge's N² matrix and its factor, and the test points at their bytes each.
    let krr = 2.0 * (rows as f64).powi(2) * 8.0;
    let test = args.test_points as f64 * BYTES_PER_TEST_POINT;
    let caches = CacheSizes::of_this_host();
    // Those first, where they are what does not fit: a grid that large is named by them, not by
    // the multiply buffers that come with it.
    if let Some(a) = available {
        let fixed = fixed_fit_bytes(&caches, 1, 2 * rows);
        if krr + fixed > a && krr >= fixed {
            return Err(Error::from(MemoryError(format!(
                "kernel ridge's {rows} × {rows} kernel matrix and its factor need about {}, more than the {} this process may use; lower --grid",
                gb(krr + fixed),
                gb(a)
            )))
            .context(flag));
        }
        if test + fixed > a && test >= fixed {
            return Err(MemoryError(format!(
                "--test-points {}: about {} to evaluate, more than the {} this process may use; lower --test-points",
                args.test_points,
                gb(test + fixed),
                gb(a)
            ))
            .into());
        }
    }
    let threads = match kernel {
        true => crate::cli::memory::check_fit(rows, 2, available, "lower --grid").context(&flag)?,
        false => crate::cli::memory::check_workers(available, 2 * rows, "lower --grid").context(&flag)?,
    };
    let Some(a) = available else { return Ok(threads) };
    // With the workers found, both again (two workers hold more than one).
    let need = krr.max(test) + fixed_fit_bytes(&caches, threads, 2 * rows);
    if need > a {
        return Err(MemoryError(format!(
            "--grid {} --test-points {}: about {} with {threads} worker(s), more than the {} this process may use; lower --grid or --test-points",
            args.grid,
            args.test_points,
            gb(need),
            gb(a)
        ))
        .into());
    }
    Ok(threads)
}

pub fn run(args: DemoArgs) -> Result<()> {
    if args.test_points == 0 {
        return Err(Error::InvalidInput("--test-points must be at least 1".into()));
    }
    crate::io::check_paths(&[], &[("--out", Some(&args.out)), ("--json", args.json.as_deref())])?;
    if let Some(dir) = &args.plots {
        crate::io::check_output_dir("--plots", dir)?;
    }
    let nominal = rr::nominal();
    let real = rr::RealRr::default();

    let mut settings = args.solver.settings()?;
    settings.source = match args.hyperparameters.as_str() {
        "paper" => crate::calibrate::HyperparameterSource::PaperRr,
        "evidence" => crate::calibrate::HyperparameterSource::Evidence,
        other => return Err(Error::InvalidInput(format!("--hyperparameters must be paper or evidence, got {other:?}"))),
    };
    if settings.source == crate::calibrate::HyperparameterSource::PaperRr && settings.steps.is_none() {
        // Two Euler steps: the reproduction's scheme (a genuine flow that generalises best there).
        settings.steps = Some(2);
    }
    // Issue 27: `--grid 3000` (9e6 rows) and `--test-points 1e11` aborted on allocation. Checked
    // before anything is allocated: the fit of every grid row as `cbd fit` checks it, kernel ridge's
    // N² matrices, the test points at their bytes each.
    let threads = check_demo_memory(&args, &settings, crate::cli::memory::available_bytes())?;
    settings.solver.memory_budget = crate::cli::memory::kernel_form_budget(threads, 2 * args.grid * args.grid);
    // A grid: its rows carry no time order (held out interleaved).
    let train = crate::data::Measurements {
        order: crate::data::RowOrder::Unordered,
        ..real.measure(&configurations(Sampling::Grid { per_axis: args.grid }, 2))
    };
    let test = real.measure(&configurations(Sampling::Uniform { count: args.test_points, seed: 2026 }, 2));
    settings.solver.threads = threads;
    let calibration = crate::memory::on_workers(threads, || crate::calibrate::calibrate(&nominal, &train, &settings))?;
    crate::face::print_calibration(&calibration, args.solver.quiet);
    let (opts, fit) = (&calibration.options, &calibration.fit);
    crate::cli::write_atomically(&args.out, &fit.blob)?;

    // The controller's view: load the blob written to disk and evaluate it.
    let blob = crate::io::read_output(&args.out)?;
    let calibrated_test = crate::predict::evaluate_blob(&blob, &test.joints)?;
    let calibrated_grid = crate::predict::evaluate_blob(&blob, &train.joints)?;

    let nominal_at = |joints: &[f64]| -> Vec<f64> { crate::nominal::positions(&nominal, joints, 2) };
    // The peer with its own hyperparameters (its GP marginal likelihood on the same rows).
    let peer = fit_kernel_ridge_peer(&nominal, &train, &Default::default())?;
    let (krr, krr_fit_seconds) = (&peer.regression, peer.seconds);

    let report = DemoReport {
        nominal: ErrorStats::of_positions(&nominal_at(&test.joints), &test.positions, 2),
        calibrated: ErrorStats::of_positions(&calibrated_test, &test.positions, 2),
        krr: ErrorStats::of_positions(&krr.predict(&nominal, &test.joints), &test.positions, 2),
        nominal_grid: ErrorStats::of_positions(&nominal_at(&train.joints), &train.positions, 2),
        calibrated_grid: ErrorStats::of_positions(&calibrated_grid, &train.positions, 2),
        krr_grid: ErrorStats::of_positions(&krr.predict(&nominal, &train.joints), &train.positions, 2),
        fit_seconds: fit.report.seconds,
        krr_fit_seconds,
        iterations: fit.report.iterations,
        blob_bytes: blob.len(),
        max_runtime_trainer_diff: fit.report.max_runtime_trainer_diff,
        n_train: train.len(),
        n_test: test.len(),
        integrator: format!("{:?}", opts.integrator.method).to_lowercase(),
        steps: opts.integrator.steps,
        sigma: calibration.hyperparameters.sigma,
        selection_seconds: calibration.evidence.as_ref().map_or(0.0, |e| e.seconds),
        calibration: calibration.to_json(),
        fit: fit.report.clone(),
    };
    print_report(&report);
    if let Some(dir) = &args.plots {
        use crate::report::plots::{demo_figures, position_errors, DemoPlotInputs};
        let nominal_map = |q: &[f64]| -> crate::Result<Vec<f64>> { Ok(nominal_at(q)) };
        let real_map = |q: &[f64]| -> crate::Result<Vec<f64>> { Ok(q.chunks_exact(2).flat_map(|x| real.position(x)).collect()) };
        let calibrated_map = |q: &[f64]| crate::predict::evaluate_blob(&blob, q);
        let test_before = position_errors(&nominal_at(&test.joints), &test.positions, 2);
        let test_after = position_errors(&calibrated_test, &test.positions, 2);
        let log: Vec<(usize, f64, f64)> = fit.report.log.iter().map(|r| (r.iteration, r.energy, r.train_rms)).collect();
        let inputs = DemoPlotInputs {
            nominal: &nominal_map,
            real: &real_map,
            calibrated: &calibrated_map,
            joint_labels: ["q1 (rad)", "q2 (rad)"],
            test_before: &test_before,
            test_after: &test_after,
            fit_log: &log,
            unit: "length units",
            heatmap_per_axis: 64,
            workspace_per_axis: 16,
        };
        let files = demo_figures(dir, &inputs)?;
        outln!("figures written to {} ({} files)", dir.display(), files.len());
    }
    outln!("model written to {}", args.out.display());
    if let Some(path) = &args.json {
        let text = serde_json::to_string_pretty(&report).map_err(Error::JsonOutput)?;
        crate::cli::write_atomically(path, text.as_bytes())?;
    }
    Ok(())
}

fn print_report(r: &DemoReport) {
    outln!("Calibration by Diffeomorphisms — planar RR benchmark (paper §4)");
    outln!("train: {} grid configurations; test: {} uniform random configurations", r.n_train, r.n_test);
    outln!("flow: {} × {} steps, σ = {:.2e}; {} iterations ({})", r.integrator, r.steps, r.sigma, r.iterations, r.fit.stop_reason);
    outln!();
    outln!("{:<28} {:>11} {:>11} {:>11} {:>11}", "position error (length units)", "mean", "median", "p99", "max");
    let row = |name: &str, s: &ErrorStats| outln!("{:<28} {:>11.3e} {:>11.3e} {:>11.3e} {:>11.3e}", name, s.mean, s.median, s.p99, s.max);
    row("random: nominal", &r.nominal);
    row("random: CbD (runtime)", &r.calibrated);
    row("random: kernel ridge", &r.krr);
    row("grid: nominal", &r.nominal_grid);
    row("grid: CbD (runtime)", &r.calibrated_grid);
    row("grid: kernel ridge", &r.krr_grid);
    outln!();
    outln!(
        "orders of magnitude (random, mean): CbD {:.2}, kernel ridge {:.2}",
        (r.nominal.mean / r.calibrated.mean).log10(),
        (r.nominal.mean / r.krr.mean).log10()
    );
    outln!(
        "fit time: CbD {:.2} s (flow {:.2} s, tangent {:.2} s, solves {:.2} s) after {:.2} s choosing its hyperparameters; kernel ridge {:.3} s with its own",
        r.fit_seconds, r.fit.seconds_flow, r.fit.seconds_tangent, r.fit.seconds_solve, r.selection_seconds, r.krr_fit_seconds
    );
    outln!(
        "blob: {} bytes; largest runtime/trainer difference at the training points: {:.1e} (relative)",
        r.blob_bytes,
        r.max_runtime_trainer_diff
    );
}

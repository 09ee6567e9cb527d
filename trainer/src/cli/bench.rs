//! `cbd bench`: fit time, iterations and peak memory against N, and the runtime's evaluation
//! time against nominal forward kinematics and against the kernel-ridge peer, measured in one run.

use crate::baselines::kernel_ridge::{fit_kernel_ridge_peer, KernelRidge};
use crate::cli::memory::MemoryError;
use crate::error::{Context, Error, Result};
use crate::simulate::{configurations, rr, Sampling};
use serde::{Deserialize, Serialize};
use std::path::PathBuf;
use std::time::Instant;

#[derive(Debug, clap::Args)]
pub struct BenchArgs {
    /// Measurement counts for the RR benchmark, comma-separated (perfect squares: a √N × √N grid).
    #[arg(long, value_delimiter = ',', default_value = "64,256,1024,4096")]
    pub sizes: Vec<usize>,
    /// Write the results as JSON here.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Replace the "## Trainer and runtime" section of this Markdown file with the results.
    #[arg(long)]
    pub markdown: Option<PathBuf>,
    /// Internal: fit one size in this process and print its JSON line (used for per-size peak memory).
    #[arg(long, hide = true)]
    pub single: Option<usize>,
    /// Internal: where the single-size run writes its blob.
    #[arg(long, hide = true)]
    pub blob_out: Option<PathBuf>,
    /// The UR5 example (model file, train.csv, test.csv) fitted as `cbd compare` fits it.
    #[arg(long, default_value = "examples/ur5")]
    pub ur5: PathBuf,
    /// Skip the UR5 row.
    #[arg(long)]
    pub no_ur5: bool,
    /// Noisy RR sizes (σ = 1e-4), comma-separated, for CbD's pipeline against kernel ridge, each with its own evidence.
    #[arg(long, value_delimiter = ',', default_value = "256,4096")]
    pub evidence_sizes: Vec<usize>,
    /// Internal: fit the UR5 example in this process and print its JSON line.
    #[arg(long, hide = true)]
    pub single_ur5: bool,
}

#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct FitBench {
    /// "rr" (the benchmark arm on a grid) or "ur5" (the laser-tracker data).
    pub case: String,
    pub n: usize,
    /// Exact Jacobians formed by the tangent flow.
    pub tangents: usize,
    /// The solver's search space: "dense" (all N·m momenta) or "eigenspace" (K_lin's dominant eigenspace).
    pub method: String,
    /// Its dimension.
    pub unknowns: usize,
    /// Choosing it (the eigen-solver; part of `seconds_solve`).
    pub seconds_basis: f64,
    /// Hyperparameter choice by the GP marginal likelihood before the fit (UR5 only; not in `seconds`).
    pub hyperparameter_seconds: f64,
    pub seconds: f64,
    pub iterations: usize,
    pub seconds_flow: f64,
    pub seconds_tangent: f64,
    pub seconds_solve: f64,
    pub peak_mib: f64,
    pub test_mean_error: f64,
}

impl FitBench {
    /// The row of a fit of `n` measurements, measured in this process (peak memory so far).
    fn of(case: &str, n: usize, r: &crate::solver::FitReport, hyperparameter_seconds: f64, test_mean_error: f64) -> FitBench {
        FitBench {
            case: case.into(),
            n,
            tangents: r.tangents,
            method: r.method.clone(),
            unknowns: r.unknowns,
            seconds_basis: r.seconds_basis,
            hyperparameter_seconds,
            seconds: r.seconds,
            iterations: r.iterations,
            seconds_flow: r.seconds_flow,
            seconds_tangent: r.seconds_tangent,
            seconds_solve: r.seconds_solve,
            peak_mib: peak_mib(),
            test_mean_error,
        }
    }
}

#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct EvalBench {
    /// Which model: the paper's kernels (the fit rows' blobs) or the demo's (evidence kernels).
    #[serde(default)]
    pub model: String,
    pub n: usize,
    pub ns: f64,
    pub nominal_ns: f64,
    pub krr_ns: f64,
    pub ratio_to_nominal: f64,
    pub ratio_to_krr: f64,
}

/// CbD's pipeline against kernel ridge, each choosing its own hyperparameters, on the same data.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct EvidenceBench {
    pub n: usize,
    /// CbD's evidence search (L-BFGS on the linearised model's marginal likelihood).
    pub cbd_selection_seconds: f64,
    pub cbd_evidence_rows: usize,
    pub cbd_evaluations: usize,
    pub cbd_scheme: String,
    pub cbd_fit_seconds: f64,
    /// The whole pipeline: evidence, scheme cross-validation, fit.
    pub cbd_seconds: f64,
    pub cbd_test_mean: f64,
    pub krr_selection_seconds: f64,
    /// Rows kernel ridge's chosen hyperparameters' likelihood was computed on (every row when its
    /// subset's choice was refined in weight space).
    #[serde(default)]
    pub krr_evidence_rows: usize,
    /// Kernel ridge's choice in one line (`baselines::kernel_ridge::correction::describe`).
    #[serde(default)]
    pub krr_choice: String,
    /// Selection and fit.
    pub krr_seconds: f64,
    pub krr_test_mean: f64,
}

#[derive(Debug, Serialize, Deserialize)]
pub struct BenchReport {
    pub machine: String,
    /// The 1-minute load average (/proc/loadavg) when the run started and when it ended: other
    /// processes sharing the cores slow the timings.
    pub load_average: [f64; 2],
    pub fit: Vec<FitBench>,
    pub eval: Vec<EvalBench>,
    #[serde(default)]
    pub evidence: Vec<EvidenceBench>,
}

fn peak_mib() -> f64 {
    let status = std::fs::read_to_string("/proc/self/status").unwrap_or_default();
    status
        .lines()
        .find(|l| l.starts_with("VmHWM:"))
        .and_then(|l| l.split_whitespace().nth(1))
        .and_then(|kb| kb.parse::<f64>().ok())
        .map(|kb| kb / 1024.0)
        .unwrap_or(f64::NAN)
}

fn machine() -> String {
    let cpu = std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|t| t.lines().find(|l| l.starts_with("model name")).map(|l| l.split(':').nth(1).unwrap_or("").trim().to_string()))
        .unwrap_or_else(|| "unknown CPU".into());
    let cores = std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1);
    format!("{cpu}, {cores} cores")
}

fn load_average() -> f64 {
    std::fs::read_to_string("/proc/loadavg").ok().and_then(|t| t.split_whitespace().next().and_then(|v| v.parse().ok())).unwrap_or(f64::NAN)
}

/// Copies of kernel ridge's N × N matrix at its peak: the kernel matrix and its Cholesky factor.
const KRR_MATRIX_COPIES: f64 = 2.0;

/// The memory check for an RR benchmark of `n` rows (`flag` names the list it came from): the
/// workers to run on, or why it cannot run here. `--sizes` fits the kernel form (`cbd fit`'s check);
/// `--evidence-sizes` runs the pipeline, whose kernel form is checked in the solver (the budget
/// [`crate::memory::kernel_form_budget`]), and kernel ridge, whose N × N matrices are checked here.
fn check_size(n: usize, flag: &str) -> Result<usize> {
    use crate::cli::memory;
    per_axis(n)?;
    let available = memory::available_bytes();
    if flag == "--sizes" {
        return memory::check_fit(n, 2, available, &format!("lower {flag}")).context(format!("{flag} {n}"));
    }
    let threads = memory::check_workers(available, 2 * n, &format!("lower {flag}")).context(format!("{flag} {n}"))?;
    let krr = KRR_MATRIX_COPIES * (n as f64).powi(2) * 8.0;
    match available {
        Some(a) if krr + memory::fixed_fit_bytes(&memory::CacheSizes::of_this_host(), threads, 2 * n) > a => {
            Err(Error::from(MemoryError(format!(
                "kernel ridge's {n} × {n} kernel matrix and its factor need about {}, more than the {} this process may use; lower {flag}",
                memory::gigabytes(krr),
                memory::gigabytes(a)
            )))
            .context(format!("{flag} {n}")))
        }
        _ => Ok(threads),
    }
}

/// A single-size run (a child `cbd bench --single …` process) failed: `what` it fitted and its
/// `error:` line ([`child_error`]).
#[derive(Debug, thiserror::Error)]
#[error("bench for {what} failed: {error}")]
pub struct ChildFailed {
    pub what: String,
    pub error: String,
}

/// What a failed single-size run said: its `error:` line (a crash's text is not relayed whole).
fn child_error(stderr: &[u8]) -> String {
    let text = String::from_utf8_lossy(stderr);
    let error = text.lines().rev().find_map(|l| l.strip_prefix("error: "));
    let last = text.lines().rev().find(|l| !l.trim().is_empty());
    crate::error::excerpt_of(error.or(last).unwrap_or("no message"), 400)
}

fn per_axis(n: usize) -> Result<usize> {
    let k = (n as f64).sqrt().round() as usize;
    if k.checked_mul(k) == Some(n) && k >= 2 {
        Ok(k)
    } else {
        Err(Error::InvalidInput(format!("size {n} is not a perfect square ≥ 4")))
    }
}

/// Fits the RR benchmark with `n` grid measurements in this process.
fn fit_one(n: usize, blob_out: &std::path::Path) -> Result<FitBench> {
    let real = rr::RealRr::default();
    let train = real.measure(&configurations(Sampling::Grid { per_axis: per_axis(n)? }, 2));
    let test = real.measure(&configurations(Sampling::Uniform { count: 1000, seed: 2026 }, 2));
    // The paper's kernels and scheme (Euler × 2) through the pipeline: the solver's scaling in N.
    let settings =
        crate::calibrate::Settings { source: crate::calibrate::HyperparameterSource::PaperRr, steps: Some(2), ..Default::default() };
    let threads = check_size(n, "--sizes")?;
    let settings = crate::calibrate::Settings { solver: crate::solver::SolverSettings { threads, ..settings.solver }, ..settings };
    let fit = crate::memory::on_workers(threads, || crate::calibrate::calibrate(&rr::nominal(), &train, &settings))?.fit;
    crate::io::write_atomically(blob_out, &fit.blob)?;
    let predicted = crate::predict::evaluate_blob(&fit.blob, &test.joints)?;
    Ok(FitBench::of("rr", n, &fit.report, 0.0, crate::report::stats::ErrorStats::of_positions(&predicted, &test.positions, 2).mean))
}

/// Fits the UR5 example's training rows as `cbd fit` and `cbd compare` do (the calibration pipeline:
/// CbD's evidence, then the scheme) in this process; test error in the data's unit on its test rows.
fn fit_ur5(dir: &std::path::Path) -> Result<FitBench> {
    let model = crate::data::model_file::load_model_file(dir.join("ur5.toml"))?;
    let spec = model.column_spec()?;
    let read = |name: &str| crate::data::csv_import::read_measurements(dir.join(name), &spec).map(|m| m.measurements);
    let (train, test) = (read("train.csv")?, read("test.csv")?);
    let c = crate::calibrate::calibrate(&model.nominal, &train, &crate::calibrate::Settings::default())?;
    let predicted = crate::predict::evaluate_blob(&c.fit.blob, &test.joints)?;
    let error = crate::report::stats::ErrorStats::of_positions(&predicted, &test.positions, train.task_dim).mean;
    let selection = c.evidence.as_ref().map_or(0.0, |e| e.seconds);
    Ok(FitBench::of("ur5", train.len(), &c.fit.report, selection, error))
}

/// CbD through the pipeline (its own evidence, cross-validated scheme) against kernel ridge (its own
/// marginal likelihood) on the noisy RR benchmark: σ = 1e-4 per coordinate on a √N × √N grid (the
/// noise of `cbd simulate --noise 1e-4`), 3000 noise-free random test configurations.
fn evidence_rr(n: usize, threads: usize, memory_budget: Option<f64>) -> Result<EvidenceBench> {
    crate::memory::on_workers(threads, || evidence_rr_on_workers(n, memory_budget))
}

fn evidence_rr_on_workers(n: usize, memory_budget: Option<f64>) -> Result<EvidenceBench> {
    let real = rr::RealRr::default();
    let mut train = real.measure(&configurations(Sampling::Grid { per_axis: per_axis(n)? }, 2));
    crate::simulate::add_noise(&mut train.positions, 1e-4, 1u64.wrapping_add(0x5eed));
    let test = real.measure(&configurations(Sampling::Uniform { count: 3000, seed: 7 }, 2));
    let nominal = rr::nominal();
    let peer = fit_kernel_ridge_peer(&nominal, &train, &Default::default())?;
    let (krr_selection_seconds, krr_seconds) = (peer.selection_seconds, peer.seconds);
    let krr_test_mean =
        crate::report::stats::ErrorStats::of_positions(&peer.regression.predict(&nominal, &test.joints), &test.positions, 2).mean;
    let t0 = Instant::now();
    let settings =
        crate::calibrate::Settings { solver: crate::solver::SolverSettings { memory_budget, ..Default::default() }, ..Default::default() };
    let c = crate::calibrate::calibrate(&nominal, &train, &settings)?;
    let cbd_seconds = t0.elapsed().as_secs_f64();
    let predicted = crate::predict::evaluate_blob(&c.fit.blob, &test.joints)?;
    let cbd_test_mean = crate::report::stats::ErrorStats::of_positions(&predicted, &test.positions, 2).mean;
    let e = c.evidence.as_ref().ok_or_else(|| Error::Internal("the pipeline ran no evidence search".into()))?;
    Ok(EvidenceBench {
        n,
        cbd_selection_seconds: e.seconds,
        cbd_evidence_rows: e.rows_used,
        cbd_evaluations: e.evaluations,
        cbd_scheme: c.scheme.label(),
        cbd_fit_seconds: c.fit.report.seconds,
        cbd_seconds,
        cbd_test_mean,
        krr_selection_seconds,
        krr_evidence_rows: peer.hyperparameters.rows_used,
        krr_choice: crate::baselines::kernel_ridge::correction::describe(&peer.hyperparameters),
        krr_seconds,
        krr_test_mean,
    })
}

/// Median of `rounds` timings of `f` over all `queries`, in ns per query.
fn time_per_query(queries: &[f64], rounds: usize, mut f: impl FnMut(&[f64]) -> f64) -> f64 {
    let mut times: Vec<f64> = (0..rounds)
        .map(|_| {
            let t0 = Instant::now();
            let mut sink = 0.0;
            for q in queries.chunks_exact(2) {
                sink += f(q);
            }
            std::hint::black_box(sink);
            t0.elapsed().as_secs_f64() * 1e9 / (queries.len() / 2) as f64
        })
        .collect();
    times.sort_by(|a, b| a.total_cmp(b));
    times[times.len() / 2]
}

fn eval_one(n: usize, blob: &[u8]) -> Result<EvalBench> {
    let model = cbd_protocol::decode(blob)?;
    let mut storage = vec![0.0; cbd_runtime::storage_len_for(&model)];
    let mut cal = cbd_runtime::Calibrator::from_model(model, &mut storage)?;
    let nominal = rr::nominal();
    let queries = configurations(Sampling::Uniform { count: 500, seed: 11 }, 2);
    let train = rr::RealRr::default().measure(&configurations(Sampling::Grid { per_axis: per_axis(n)? }, 2));
    let mut kernel = cbd_protocol::paper_rr::joint_kernel();
    kernel.gamma = 1.0;
    let krr = KernelRidge::fit(&nominal, &train, kernel, 1e-12)?;
    let rounds = 7;
    let ns = time_per_query(&queries, rounds, |q| cal.evaluate(q).map(|e| e.position()[0]).unwrap_or(f64::NAN));
    let nominal_ns = time_per_query(&queries, rounds, |q| cbd_runtime::internals::kinematics::forward_kinematics(&nominal, q).position[0]);
    // Like with like: the peer's position and Jacobian, its kernel from the same feature table.
    let krr_ns = time_per_query(&queries, rounds, |q| {
        let e = krr.evaluate(&nominal, q);
        e.position[0] + e.jacobian[0][0]
    });
    let model = String::new();
    Ok(EvalBench { model, n, ns, nominal_ns, krr_ns, ratio_to_nominal: ns / nominal_ns, ratio_to_krr: ns / krr_ns })
}

/// The demo's model (`cbd demo`: the RR grid of 16 × 16, kernels by CbD's evidence, the pipeline's
/// representation and scheme) timed as [`eval_one`] does.
fn eval_demo() -> Result<EvalBench> {
    let train = rr::RealRr::default().measure(&configurations(Sampling::Grid { per_axis: 16 }, 2));
    let settings = crate::calibrate::Settings::default();
    let c = crate::calibrate::calibrate(&rr::nominal(), &train, &settings)?;
    let mut e = eval_one(256, &c.fit.blob)?;
    let i = c.options.integrator;
    e.model = format!("demo ({}, {:?} × {})", c.fit.report.representation, i.method, i.steps).to_lowercase();
    Ok(e)
}

pub fn run(args: BenchArgs) -> Result<()> {
    if let Some(n) = args.single {
        let blob_out = args.blob_out.clone().ok_or_else(|| Error::InvalidInput("--single needs --blob-out".into()))?;
        let fit = fit_one(n, &blob_out)?;
        outln!("{}", serde_json::to_string(&fit).map_err(Error::JsonOutput)?);
        return Ok(());
    }
    if args.single_ur5 {
        let fit = fit_ur5(&args.ur5)?;
        outln!("{}", serde_json::to_string(&fit).map_err(Error::JsonOutput)?);
        return Ok(());
    }
    // `--markdown` is edited in place: an output, and read only to keep its other sections.
    crate::io::check_paths(&[], &[("--json", args.json.as_deref()), ("--markdown", args.markdown.as_deref())])?;
    // Every size is checked before the first fit: a size too large for the memory is refused up front.
    // The evidence sizes run in this process, on the workers found here: a check after the earlier
    // runs would count a workspace they already hold twice (the address space includes it).
    for &n in &args.sizes {
        check_size(n, "--sizes")?;
    }
    let evidence_threads: Vec<usize> = args.evidence_sizes.iter().map(|&n| check_size(n, "--evidence-sizes")).collect::<Result<_, _>>()?;
    let largest = 2 * args.evidence_sizes.iter().copied().max().unwrap_or(0);
    let budget = crate::cli::memory::kernel_form_budget(evidence_threads.iter().copied().max().unwrap_or(1), largest);
    // The UR5 example's files are checked before any fit, not after minutes of them.
    if !args.no_ur5 {
        for file in ["ur5.toml", "train.csv", "test.csv"] {
            let path = args.ur5.join(file);
            if !path.is_file() {
                return Err(Error::Path { path, reason: "the UR5 example (--ur5 DIR) needs this file; --no-ur5 skips it".into() });
            }
        }
    }
    let exe = std::env::current_exe().map_err(|e| Error::stage("bench", e))?;
    let mut report = BenchReport {
        machine: machine(),
        load_average: [load_average(), f64::NAN],
        fit: Vec::new(),
        eval: Vec::new(),
        evidence: Vec::new(),
    };
    for &n in &args.sizes {
        per_axis(n)?;
        errln!("fitting N = {n} …");
        // One process per size, so each peak-memory figure is that size's own.
        let blob_path = std::env::temp_dir().join(format!("cbd-bench-{}-{n}.blob", std::process::id()));
        let out = std::process::Command::new(&exe)
            .args(["bench", "--single", &n.to_string(), "--blob-out"])
            .arg(&blob_path)
            .output()
            .map_err(|e| Error::stage("bench", e))?;
        if !out.status.success() {
            return Err(Error::stage("bench", ChildFailed { what: format!("N = {n}"), error: child_error(&out.stderr) }));
        }
        let line = String::from_utf8_lossy(&out.stdout);
        let fit: FitBench = serde_json::from_str(line.trim()).map_err(Error::JsonOutput).context(format!("bench output for N = {n}"))?;
        errln!(
            "  {:.2} s, {} iterations, peak {:.0} MiB, test mean error {:.2e}",
            fit.seconds,
            fit.iterations,
            fit.peak_mib,
            fit.test_mean_error
        );
        report.fit.push(fit);
        let blob = std::fs::read(&blob_path).map_err(|e| Error::io(&blob_path, e))?;
        let _ = std::fs::remove_file(&blob_path);
        let mut e = eval_one(n, &blob)?;
        e.model = "paper (kernel, euler × 2)".into();
        errln!("  evaluation {:.0} ns ({:.1}× nominal FK, {:.2}× kernel ridge)", e.ns, e.ratio_to_nominal, e.ratio_to_krr);
        report.eval.push(e);
    }
    if !args.sizes.is_empty() {
        errln!("the demo's model (N = 256, evidence kernels) …");
        let e = eval_demo()?;
        errln!("  {}: evaluation {:.0} ns ({:.1}× nominal FK, {:.2}× kernel ridge)", e.model, e.ns, e.ratio_to_nominal, e.ratio_to_krr);
        report.eval.push(e);
    }
    if !args.no_ur5 {
        errln!("fitting the UR5 example ({}) …", args.ur5.display());
        let out = std::process::Command::new(&exe)
            .args(["bench", "--single-ur5", "--ur5"])
            .arg(&args.ur5)
            .output()
            .map_err(|e| Error::stage("bench", e))?;
        if !out.status.success() {
            return Err(Error::stage("bench", ChildFailed { what: "the UR5 example".into(), error: child_error(&out.stderr) }));
        }
        let fit: FitBench =
            serde_json::from_str(String::from_utf8_lossy(&out.stdout).trim()).map_err(Error::JsonOutput).context("UR5 bench output")?;
        errln!(
            "  {:.2} s, {} iterations, peak {:.0} MiB, test mean error {:.3e}",
            fit.seconds,
            fit.iterations,
            fit.peak_mib,
            fit.test_mean_error
        );
        report.fit.push(fit);
    }
    for (&n, &threads) in args.evidence_sizes.iter().zip(&evidence_threads) {
        errln!("noisy RR, N = {n}: CbD pipeline and kernel ridge, each with its own evidence …");
        let e = evidence_rr(n, threads, budget)?;
        errln!(
            "  CbD {:.3e} (selection {:.2} s on {} rows, pipeline {:.2} s, {}); kernel ridge {:.3e} (selection {:.2} s on {} rows, with the fit {:.2} s)\n  kernel ridge: {}",
            e.cbd_test_mean,
            e.cbd_selection_seconds,
            e.cbd_evidence_rows,
            e.cbd_seconds,
            e.cbd_scheme,
            e.krr_test_mean,
            e.krr_selection_seconds,
            e.krr_evidence_rows,
            e.krr_seconds,
            e.krr_choice
        );
        report.evidence.push(e);
    }
    report.load_average[1] = load_average();
    if let Some(path) = &args.json {
        crate::cli::write_atomically(path, serde_json::to_string_pretty(&report).map_err(Error::JsonOutput)?.as_bytes())?;
    }
    let table = markdown(&report);
    outln!("{table}");
    if let Some(path) = &args.markdown {
        replace_section(path, "## Trainer and runtime", &table)?;
    }
    Ok(())
}

/// Least-squares slope of log(y) against log(x).
fn exponent(points: &[(f64, f64)]) -> f64 {
    let n = points.len() as f64;
    let (sx, sy) = points.iter().fold((0.0, 0.0), |(a, b), (x, y)| (a + x.ln(), b + y.ln()));
    let (mx, my) = (sx / n, sy / n);
    let (num, den) = points.iter().fold((0.0, 0.0), |(a, b), (x, y)| (a + (x.ln() - mx) * (y.ln() - my), b + (x.ln() - mx).powi(2)));
    num / den
}

fn markdown(r: &BenchReport) -> String {
    let mut s = String::from("## Trainer and runtime\n\n");
    s += &format!("Machine: {}. Command: `cargo run --release -p cbd-trainer --bin cbd -- bench --markdown BENCHMARKS.md`.\n", r.machine);
    s += &format!(
        "1-minute load average when the run started and ended: {:.2} and {:.2} (other work shares the cores: above about 1, timings stretch).\n",
        r.load_average[0], r.load_average[1]
    );
    s += "RR benchmark (docs/DESIGN.md, the paper's arm) with the paper's kernels, σ = 1e-6 and Euler × 2 (`cbd demo --hyperparameters paper`: the\nnonlinear solver's scaling in N), N grid measurements; test error on 1000 random configurations.\n";
    s +=
        "Solver: Gauss–Newton from the linearised model's solution (QR of the stacked [J/σ; Lᵀ], damping only after a failed step, chord\n";
    s += "steps reusing a factorisation while they pay); stops when an exact step lowers the energy by < 1e-5 (relative) or moves no\n";
    s += "training prediction by 1e-10 (normalised units). The search space is chosen automatically: up to 1024 unknowns all N·m\n";
    s += "momenta (\"dense\": N·m tangent directions per Jacobian, a 2Nm × Nm QR, O(N³)); above, when K_lin's dominant eigenspace is\n";
    s += "small next to N·m, P0 = S c with S its eigenvectors above 3e-14 of the largest eigenvalue (\"eigenspace\", from randomised\n";
    s += "subspace iteration; its size does not grow with N for smooth kernels: r tangent directions per Jacobian, an (Nm + r) × r QR,\n";
    s += "O(N² r) per iteration, memory O(N² + N r)). One process per row (peak MiB = its VmHWM). Timings on 2 shared cores are noisy (±20 % when idle; see the load above).\n\n";
    s += "UR5: the example's 1000 training rows fitted as `cbd fit` and `cbd compare` fit them (the calibration pipeline: CbD's own\n";
    s += "evidence on 400 evenly spaced rows, then Euler × 1, the linearised model, solved in closed form), test error in mm on its 20\n";
    s += "test rows; the evidence search is not in fit s.\n";
    s += "Derivatives = tangent flow (exact Jacobians; the first is in closed form); solves = eigenspace (if tried), QR factorisations and solves.\n\n";
    s += "| case | N | method (unknowns) | fit s | iterations | exact Jacobians | flow s | derivatives s | solves s | peak MiB | test mean error |\n";
    s += "|---|---|---|---|---|---|---|---|---|---|---|\n";
    for f in &r.fit {
        s += &format!(
            "| {} | {} | {} ({}) | {:.2} | {} | {} | {:.2} | {:.2} | {:.2} | {:.0} | {:.2e} |\n",
            f.case,
            f.n,
            f.method,
            f.unknowns,
            f.seconds,
            f.iterations,
            f.tangents,
            f.seconds_flow,
            f.seconds_tangent,
            f.seconds_solve,
            f.peak_mib,
            f.test_mean_error
        );
    }
    s += "\nEvaluation, one core, median of 7 rounds over 500 random configurations: the runtime's `Calibrator::evaluate` (position and exact\n";
    s += "Jacobian of the calibrated model), the nominal forward kinematics (position and Jacobian), and the kernel-ridge peer fitted on the\n";
    s += "same grid (position and Jacobian; its kernel from the same precomputed cos/sin feature table, one `exp` per training point).\n";
    s += "The last row is the demo's model (`cbd demo`: kernels from CbD's evidence, the pipeline's representation and scheme).\n";
    s += "\n| model | N | runtime eval ns | nominal FK ns | kernel ridge ns | ratio to nominal | ratio to kernel ridge |\n|---|---|---|---|---|---|---|\n";
    for e in &r.eval {
        s += &format!(
            "| {} | {} | {:.0} | {:.0} | {:.0} | {:.1} | {:.2} |\n",
            e.model, e.n, e.ns, e.nominal_ns, e.krr_ns, e.ratio_to_nominal, e.ratio_to_krr
        );
    }
    if !r.evidence.is_empty() {
        s += "\nHyperparameters chosen by each model's own evidence, same data, same run: noisy RR benchmark (σ = 1e-4 per coordinate,\n";
        s += "√N × √N grid, as `cbd simulate --noise 1e-4`; 3000 noise-free random test configurations). CbD: `crate::calibrate` (L-BFGS on\n";
        s += "the linearised model's log marginal likelihood, analytic gradient, 4 starts screened for 10 iterations on ≤ 120 rows, the best two basins continued there, then the best (and a runner-up in another basin) refined on ≤ 600 rows,\n";
        s += "and above that on every row in weight space (the kernels' truncated expansions, O(N m r²)); then the scheme by 4-fold\n";
        s += "cross-validation when N·m ≤ 1024, then the fit: Euler × 1 in closed form, in weight space above N·m = 8192). Kernel ridge: its GP\n";
        s += "marginal likelihood (pattern search on ≤ 1500 evenly spaced rows, above that its choice refined on every row in weight space).\n";
        s += "\n| N | CbD test mean | kernel ridge test mean | ratio | CbD selection s | kernel ridge selection s | ratio | CbD evidence rows (evaluations) | kernel ridge evidence rows | CbD scheme | CbD pipeline s |\n|---|---|---|---|---|---|---|---|---|---|---|\n";
        for e in &r.evidence {
            s += &format!(
                "| {} | {:.3e} | {:.3e} | {:.2} | {:.2} | {:.2} | {:.1} | {} ({}) | {} | {} | {:.2} |\n",
                e.n,
                e.cbd_test_mean,
                e.krr_test_mean,
                e.cbd_test_mean / e.krr_test_mean,
                e.cbd_selection_seconds,
                e.krr_selection_seconds,
                e.cbd_selection_seconds / e.krr_selection_seconds,
                e.cbd_evidence_rows,
                e.cbd_evaluations,
                e.krr_evidence_rows,
                e.cbd_scheme,
                e.cbd_seconds
            );
        }
    }
    let rr: Vec<&FitBench> = r.fit.iter().filter(|f| f.case == "rr").collect();
    if rr.len() >= 2 {
        let fit_exp = exponent(&rr.iter().map(|f| (f.n as f64, f.seconds)).collect::<Vec<_>>());
        let mem_exp = exponent(&rr.iter().map(|f| (f.n as f64, f.peak_mib)).collect::<Vec<_>>());
        let eval_exp = exponent(&r.eval.iter().filter(|e| !e.model.starts_with("demo")).map(|e| (e.n as f64, e.ns)).collect::<Vec<_>>());
        s += &format!("\nMeasured growth on the RR rows (least-squares exponent of N): fit time N^{fit_exp:.2}, peak memory N^{mem_exp:.2}, evaluation time N^{eval_exp:.2}");
        let (a, b) = (rr[rr.len() - 2], rr[rr.len() - 1]);
        let local = |x: f64, y: f64| (y / x).ln() / (b.n as f64 / a.n as f64).ln();
        s += &format!(
            "; between N = {} and {}: fit time N^{:.2}, peak memory N^{:.2}.\n",
            a.n,
            b.n,
            local(a.seconds, b.seconds),
            local(a.peak_mib, b.peak_mib)
        );
    }
    s
}

/// Replaces `heading`'s section (up to the next `## `) in `path`, or appends it.
fn replace_section(path: &std::path::Path, heading: &str, body: &str) -> Result<()> {
    let text = std::fs::read_to_string(path).unwrap_or_else(|_| String::from("# Benchmarks\n\n"));
    let new = match text.find(heading) {
        Some(start) => {
            let rest = &text[start + heading.len()..];
            let end = rest.find("\n## ").map(|i| start + heading.len() + i + 1).unwrap_or(text.len());
            format!("{}{}{}", &text[..start], body.trim_end().to_owned() + "\n\n", &text[end..])
        }
        None => format!("{}\n{}\n", text.trim_end(), body),
    };
    crate::cli::write_atomically(path, new.as_bytes())
}

//! `cbd fit`: train a model blob from measured data.

use crate::cli::{load_nominal, ModelArgs};
use crate::solver::{fit_cbd, CbdOptions};
use std::path::PathBuf;

#[derive(Debug, clap::Args)]
pub struct FitArgs {
    #[command(flatten)]
    pub model: ModelArgs,
    /// Training measurements (CSV).
    #[arg(long)]
    pub data: PathBuf,
    /// Output blob.
    #[arg(long)]
    pub out: PathBuf,
    /// First calibrate the DH parameters (plus base and tool) by Levenberg–Marquardt, then fit
    /// the diffeomorphic correction on top; the blob carries the calibrated chain.
    #[arg(long)]
    pub dh_first: bool,
    #[command(flatten)]
    pub solver: SolverArgs,
}

/// Hyperparameters and scheme; anything left unset uses the defaults for the model.
#[derive(Debug, Clone, clap::Args)]
pub struct SolverArgs {
    /// Noise level σ of energy (16), in the data's length unit.
    #[arg(long)]
    pub sigma: Option<f64>,
    /// Task-space kernel width a, in the data's length unit.
    #[arg(long)]
    pub task_width: Option<f64>,
    /// Joint kernel b (periodic axes), shared by all joints.
    #[arg(long)]
    pub joint_b: Option<f64>,
    /// Joint kernel amplitude γ.
    #[arg(long)]
    pub gamma: Option<f64>,
    /// euler, heun or rk4 (default euler).
    #[arg(long)]
    pub integrator: Option<String>,
    /// Integration steps; training optimises exactly this discrete flow (default: 2 for the
    /// planar RR arm, 1 — the linearised model, fast for large N — for model files).
    #[arg(long)]
    pub steps: Option<u16>,
    #[arg(long, default_value_t = 30)]
    pub max_iterations: usize,
    /// Drop the −(div v) P term from the momentum law.
    #[arg(long)]
    pub no_divergence: bool,
    /// auto, dense or eigenspace: search all N·m momenta (O(N³) per iteration), or K_lin's dominant
    /// eigenspace (O(N² r), r independent of N for smooth kernels); auto picks by problem size and spectrum.
    #[arg(long)]
    pub solver: Option<String>,
    #[arg(long)]
    pub quiet: bool,
}

/// `--solver` values.
pub fn parse_solver(name: &str) -> Result<crate::solver::SolverMethod, String> {
    use crate::solver::SolverMethod;
    match name {
        "auto" => Ok(SolverMethod::Auto),
        "dense" => Ok(SolverMethod::Dense),
        "eigenspace" => Ok(SolverMethod::Eigenspace),
        other => Err(format!("--solver must be auto, dense or eigenspace, got {other:?}")),
    }
}

impl SolverArgs {
    /// Options for `nominal` and `data`: the paper's RR values for a planar 2-joint arm, otherwise
    /// data-scaled defaults (task space normalised to unit RMS radius).
    /// Rejects out-of-range values before any work, naming the flag.
    pub fn validate(&self) -> Result<(), String> {
        for (flag, value) in
            [("--sigma", self.sigma), ("--task-width", self.task_width), ("--joint-b", self.joint_b), ("--gamma", self.gamma)]
        {
            if let Some(v) = value {
                if !(v.is_finite() && v > 0.0) {
                    return Err(format!("{flag} must be a finite number > 0, got {v}"));
                }
            }
        }
        if let Some(steps) = self.steps {
            if steps == 0 || steps > cbd_protocol::MAX_STEPS {
                return Err(format!("--steps must be between 1 and {}, got {steps}", cbd_protocol::MAX_STEPS));
            }
        }
        if let Some(method) = &self.integrator {
            crate::cli::demo::parse_integrator(method)?;
        }
        if let Some(solver) = &self.solver {
            parse_solver(solver)?;
        }
        if self.max_iterations == 0 {
            return Err("--max-iterations must be at least 1".into());
        }
        Ok(())
    }

    pub fn options(&self, nominal: &cbd_protocol::NominalModel, data: &crate::data::Measurements) -> Result<CbdOptions, String> {
        self.validate()?;
        let mut opts = CbdOptions::paper_rr();
        let n = nominal.n_joints();
        if !(matches!(nominal, cbd_protocol::NominalModel::PlanarChain { .. }) && n == 2) {
            // Kernel widths and σ by the marginal likelihood of the residual GP on the training
            // rows (DESIGN.md §3), mapped onto the flow's linearisation.
            let search = crate::kernels::hyperparameters::SearchOptions::default();
            let h = crate::kernels::hyperparameters::choose_hyperparameters(nominal, data, &search).map_err(|e| e.to_string())?;
            opts = crate::kernels::cbd_options_from_gp(&h, data);
            opts.integrator.steps = 1;
            if !self.quiet {
                eprintln!(
                    "hyperparameters (GP marginal likelihood {:.2} on {} rows): joint kernel {:?}, noise σ {:.4} (data units)",
                    h.log_marginal_likelihood,
                    h.rows_used,
                    h.kernel.axes.iter().collect::<Vec<_>>(),
                    h.noise_sigma_data_units()
                );
            }
        }
        let scale = opts.normalisation.task_scale;
        if let Some(s) = self.sigma {
            opts.sigma = s / scale;
        }
        if let Some(a) = self.task_width {
            opts.task_kernel.width = a / scale;
        }
        if let Some(g) = self.gamma {
            opts.joint_kernel.gamma = g;
        }
        if let Some(b) = self.joint_b {
            for axis in opts.joint_kernel.axes.iter_mut() {
                if let cbd_protocol::JointKernelAxis::Periodic { b: old } = axis {
                    *old = b;
                }
            }
        }
        if let Some(method) = &self.integrator {
            opts.integrator.method = crate::cli::demo::parse_integrator(method)?;
        }
        if let Some(steps) = self.steps {
            opts.integrator.steps = steps;
        }
        opts.max_iterations = self.max_iterations;
        if let Some(solver) = &self.solver {
            opts.method = parse_solver(solver)?;
        }
        opts.verbose = !self.quiet;
        if self.no_divergence {
            opts.law = cbd_protocol::MomentumLaw::WithoutDivergence;
        }
        Ok(opts)
    }
}

pub fn run(args: FitArgs) -> Result<(), String> {
    args.solver.validate()?;
    crate::cli::check_output_dir(&args.out)?;
    let (nominal, spec) = load_nominal(&args.model)?;
    let imported = crate::data::csv_import::read_measurements(&args.data, &spec).map_err(|e| e.to_string())?;
    for w in imported.warnings(&args.data) {
        eprintln!("warning: {w}");
    }
    let data = imported.measurements;
    let nominal = if args.dh_first {
        let options = crate::baselines::dh_calibration::DhCalibrationOptions::default();
        let dh = crate::baselines::dh_calibration::calibrate_dh(&nominal, &data, &options).map_err(|e| e.to_string())?;
        eprintln!(
            "DH calibration: {} iterations, rank {}/{}, training RMS {:.4e}",
            dh.stats.iterations, dh.stats.rank, dh.stats.n_parameters, dh.stats.final_rms
        );
        dh.model
    } else {
        nominal
    };
    let opts = args.solver.options(&nominal, &data)?;
    let fit = fit_cbd(&nominal, &data, &opts).map_err(|e| format!("{}: {e}", args.data.display()))?;
    crate::cli::write_atomically(&args.out, &fit.blob)?;
    let r = &fit.report;
    let last = r.log.last().map(|l| l.train_rms).unwrap_or(f64::NAN);
    println!(
        "fitted {} measurements in {:.2} s: {} iterations ({}), training RMS error {:.3e}; blob {} bytes written to {}",
        data.len(),
        r.seconds,
        r.iterations,
        r.stop_reason,
        last,
        fit.blob.len(),
        args.out.display()
    );
    Ok(())
}

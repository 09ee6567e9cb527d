//! The options of the one calibration pipeline as a front takes them: flags (clap) and keyword
//! arguments (serde) alike, one set of defaults, checked once, made `crate::calibrate::Settings`.

use crate::error::{Error, Result};

/// Hyperparameters and scheme; anything left unset is chosen by the pipeline (`crate::calibrate`):
/// CbD's own evidence on the training rows, then the scheme by cross-validation. Every length is in
/// the data's unit and means the same in `fit`, `compare`, `diagnose` and `demo`; a value given
/// replaces that one hyperparameter of the search's result.
#[derive(Debug, Clone, clap::Args, serde::Deserialize)]
pub struct PipelineOptions {
    /// The configuration-dependent task field γ_C exp(Σ_d c_d (cos(q_d − q'_d) − 1)) exp(−|x − x'|²/2a_C²) I
    /// beside CbD's two fields (docs/DESIGN.md §16): auto keeps it when CbD's evidence gains more than
    /// ½ ln(N m) nats per added hyperparameter, searched after the geometry choice; on always adds it,
    /// off never. With it the blob is Euler × 1 in the kernel form (no scheme choice, no expansion).
    #[arg(long, value_enum, default_value_t = defaults::configuration_field())]
    #[serde(default = "defaults::configuration_field")]
    pub configuration_field: crate::calibrate::ConfigurationField,
    /// Measurement noise σ per coordinate, in the data's length unit.
    #[arg(long)]
    pub sigma: Option<f64>,
    /// Task-space kernel width a, in the data's length unit.
    #[arg(long)]
    pub task_width: Option<f64>,
    /// Task-space field variance γ_W, in the data's length unit squared.
    #[arg(long)]
    pub task_gamma: Option<f64>,
    /// Joint kernel b of every revolute joint (periodic kernel exp(b (cos Δ − 1))).
    #[arg(long)]
    pub joint_b: Option<f64>,
    /// Joint-space field variance γ_V (rad² for revolute joints).
    #[arg(long)]
    pub gamma: Option<f64>,
    /// euler, heun or rk4 (default euler).
    #[arg(long)]
    pub integrator: Option<String>,
    /// Integration steps; training optimises exactly this discrete flow (default: 1 or 2, chosen
    /// by cross-validation on the training rows).
    #[arg(long)]
    pub steps: Option<u16>,
    #[arg(long, default_value_t = defaults::max_iterations())]
    #[serde(default = "defaults::max_iterations")]
    pub max_iterations: usize,
    /// Drop the −(div v) P term from the momentum law.
    #[arg(long)]
    #[serde(default)]
    pub no_divergence: bool,
    /// auto, dense or eigenspace: search all N·m momenta (O(N³) per iteration), or K_lin's dominant
    /// eigenspace (O(N² r), r independent of N for smooth kernels); auto picks by problem size and spectrum.
    #[arg(long)]
    pub solver: Option<String>,
    /// How the runtime evaluates the fields: auto (the kernels' own expansion when it is shorter
    /// than the momenta or the momenta cancel), kernel (points and momenta only) or expansion.
    #[arg(long, value_enum, default_value_t = crate::expansion::Representation::default())]
    #[serde(default)]
    pub representation: crate::expansion::Representation,
    #[arg(long)]
    #[serde(default)]
    pub quiet: bool,
}

/// The options' defaults, one source for the command line (clap) and the Python package's keyword
/// arguments (serde): `cli::settings_tests` checks that both read the same arguments from nothing.
pub mod defaults {
    pub fn configuration_field() -> crate::calibrate::ConfigurationField {
        crate::calibrate::ConfigurationField::Auto
    }

    pub fn max_iterations() -> usize {
        30
    }

    pub fn geometry() -> crate::calibrate::Geometry {
        crate::calibrate::Geometry::Auto
    }
}

/// `--solver` values.
fn parse_solver(name: &str) -> Result<crate::solver::SolverMethod> {
    use crate::solver::SolverMethod;
    match name {
        "auto" => Ok(SolverMethod::Auto),
        "dense" => Ok(SolverMethod::Dense),
        "eigenspace" => Ok(SolverMethod::Eigenspace),
        other => Err(Error::InvalidInput(format!("--solver must be auto, dense or eigenspace, got {other:?}"))),
    }
}

impl PipelineOptions {
    /// Rejects out-of-range values before any work, naming the flag.
    pub fn validate(&self) -> Result<()> {
        for (flag, value) in [
            ("--sigma", self.sigma),
            ("--task-width", self.task_width),
            ("--task-gamma", self.task_gamma),
            ("--joint-b", self.joint_b),
            ("--gamma", self.gamma),
        ] {
            if let Some(v) = value {
                // Squares and products of two such values must stay finite (σ², γ |Dk0|², a²).
                if let Some(refusal) = crate::limits::positive_scale_out_of_bounds(flag, v) {
                    return Err(Error::InvalidInput(refusal));
                }
            }
        }
        if let Some(steps) = self.steps {
            if steps == 0 || steps > cbd_protocol::MAX_STEPS {
                return Err(Error::InvalidInput(format!("--steps must be between 1 and {}, got {steps}", cbd_protocol::MAX_STEPS)));
            }
        }
        if let Some(method) = &self.integrator {
            parse_integrator(method)?;
        }
        if let Some(solver) = &self.solver {
            parse_solver(solver)?;
        }
        if self.max_iterations == 0 {
            return Err(Error::InvalidInput("--max-iterations must be at least 1".into()));
        }
        Ok(())
    }

    /// The pipeline's settings for these flags.
    pub fn settings(&self) -> Result<crate::calibrate::Settings> {
        self.validate()?;
        let overrides = crate::calibrate::Overrides {
            sigma: self.sigma,
            task_width: self.task_width,
            task_gamma: self.task_gamma,
            joint_b: self.joint_b,
            joint_gamma: self.gamma,
        };
        let mut s = crate::calibrate::Settings { overrides, ..Default::default() };
        if let Some(method) = &self.integrator {
            s.integrator = Some(parse_integrator(method)?);
        }
        s.steps = self.steps;
        s.configuration = self.configuration_field;
        s.solver.max_iterations = self.max_iterations;
        if let Some(solver) = &self.solver {
            s.solver.method = parse_solver(solver)?;
        }
        s.solver.verbose = !self.quiet;
        s.solver.representation = self.representation;
        if self.no_divergence {
            s.solver.law = cbd_protocol::MomentumLaw::HamiltonianWithoutDivergence;
        }
        Ok(s)
    }
}

/// The integrator a command-line name stands for.
fn parse_integrator(name: &str) -> Result<cbd_protocol::IntegratorMethod> {
    match name.to_ascii_lowercase().as_str() {
        "euler" => Ok(cbd_protocol::IntegratorMethod::Euler),
        "heun" => Ok(cbd_protocol::IntegratorMethod::Heun),
        "rk4" => Ok(cbd_protocol::IntegratorMethod::Rk4),
        other => Err(Error::InvalidInput(format!("unknown integrator `{other}` (expected euler, heun or rk4)"))),
    }
}

//! What several commands share: their argument groups (the model file, CbD's hyperparameters and
//! scheme) and the helpers behind them (CbD's fit for those flags, what a fit chose, a blob that
//! does not fit its model). Commands import from here, from `blob_rows` (a blob read and evaluated on
//! rows) and from `cli` itself, never from each other.

use crate::error::{Error, Result};

/// The nominal model: a model file, or the built-in planar RR arm.
#[derive(Debug, Clone, clap::Args, serde::Deserialize)]
pub struct ModelArgs {
    /// Model file (TOML: DH table or URDF, units, CSV columns). Without it: the paper's RR arm,
    /// CSV columns q1, q2 (radians), x, y.
    #[arg(long)]
    pub model: Option<std::path::PathBuf>,
}

/// Hyperparameters and scheme; anything left unset is chosen by the pipeline (`crate::calibrate`):
/// CbD's own evidence on the training rows, then the scheme by cross-validation. Every length is in
/// the data's unit and means the same in `fit`, `compare`, `diagnose` and `demo`; a value given
/// replaces that one hyperparameter of the search's result.
#[derive(Debug, Clone, clap::Args, serde::Deserialize)]
pub struct SolverArgs {
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

/// A list flag given as one value or as a list (`effect="…"` or `effect=["…", "…"]`).
pub fn one_or_many<'de, D: serde::Deserializer<'de>>(deserializer: D) -> std::result::Result<Vec<String>, D::Error> {
    #[derive(serde::Deserialize)]
    #[serde(untagged)]
    enum OneOrMany {
        One(String),
        Many(Vec<String>),
    }
    Ok(match <OneOrMany as serde::Deserialize>::deserialize(deserializer)? {
        OneOrMany::One(v) => vec![v],
        OneOrMany::Many(v) => v,
    })
}

/// The flags' defaults, one source for the command line (clap) and the Python package's keyword
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

    pub fn harmonics() -> u8 {
        3
    }

    pub fn folds() -> usize {
        5
    }

    pub fn margin() -> f64 {
        0.05
    }

    pub fn robot() -> String {
        "rr".into()
    }

    pub fn sampling() -> String {
        "grid".into()
    }

    pub fn grid() -> usize {
        16
    }

    pub fn count() -> usize {
        3000
    }

    pub fn seed() -> u64 {
        1
    }
}

/// `--solver` values.
pub fn parse_solver(name: &str) -> Result<crate::solver::SolverMethod> {
    use crate::solver::SolverMethod;
    match name {
        "auto" => Ok(SolverMethod::Auto),
        "dense" => Ok(SolverMethod::Dense),
        "eigenspace" => Ok(SolverMethod::Eigenspace),
        other => Err(Error::InvalidInput(format!("--solver must be auto, dense or eigenspace, got {other:?}"))),
    }
}

/// Largest `--sigma` accepted, relative to the training positions' spread ([`SolverArgs::check_against`]).
pub const MAX_SIGMA_PER_EXTENT: f64 = 1e3;

impl SolverArgs {
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

    /// `--sigma` against the training rows at `path`: a noise σ over [`MAX_SIGMA_PER_EXTENT`] ×
    /// the positions' spread (RMS distance from their mean) would swamp every measurement — a σ
    /// given in another unit — and the fit would fail later with a message about diverging flows.
    pub fn check_against(&self, data: &crate::data::Measurements, path: &std::path::Path) -> Result<()> {
        let (Some(sigma), m) = (self.sigma, data.task_dim) else { return Ok(()) };
        let n = data.len();
        if n == 0 || m == 0 {
            return Ok(());
        }
        let mean: Vec<f64> = (0..m).map(|c| (0..n).map(|i| data.position(i)[c]).sum::<f64>() / n as f64).collect();
        let spread = ((0..n).map(|i| data.position(i).iter().zip(&mean).map(|(p, c)| (p - c) * (p - c)).sum::<f64>()).sum::<f64>()
            / n as f64)
            .sqrt();
        if spread > 0.0 && sigma > MAX_SIGMA_PER_EXTENT * spread {
            return Err(Error::InvalidInput(format!(
                "--sigma {} is over {MAX_SIGMA_PER_EXTENT} × the spread of {}'s positions (RMS {} from their mean): a noise that size would swamp every measurement; give σ in the data's length unit",
                crate::error::as_written(sigma),
                path.display(),
                crate::error::number(spread)
            )));
        }
        Ok(())
    }

    /// The pipeline's settings for these flags.
    pub fn settings(&self) -> Result<crate::calibrate::Settings> {
        self.validate()?;
        let mut s = crate::calibrate::Settings::default();
        s.overrides = crate::calibrate::Overrides {
            sigma: self.sigma,
            task_width: self.task_width,
            task_gamma: self.task_gamma,
            joint_b: self.joint_b,
            joint_gamma: self.gamma,
        };
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
pub fn parse_integrator(name: &str) -> Result<cbd_protocol::IntegratorMethod> {
    match name.to_ascii_lowercase().as_str() {
        "euler" => Ok(cbd_protocol::IntegratorMethod::Euler),
        "heun" => Ok(cbd_protocol::IntegratorMethod::Heun),
        "rk4" => Ok(cbd_protocol::IntegratorMethod::Rk4),
        other => Err(Error::InvalidInput(format!("unknown integrator `{other}` (expected euler, heun or rk4)"))),
    }
}

/// Prints what the pipeline chose (stderr) and its warnings.
pub fn print_calibration(c: &crate::calibrate::Calibration, quiet: bool) {
    if let Some(dh) = &c.dh {
        errln!("DH calibration: {} iterations, rank {}/{}, training RMS {:.4e}", dh.iterations, dh.rank, dh.n_parameters, dh.final_rms);
    }
    if !quiet {
        errln!("{}", c.geometry.describe());
        if let Some(f) = &c.configuration {
            errln!("{}", f.describe());
        }
        match &c.evidence {
            Some(e) => errln!(
                "hyperparameters (CbD evidence {:.2} on {} rows, {} evaluations, {:.2} s): {}",
                e.log_evidence,
                e.rows_used,
                e.evaluations,
                e.seconds,
                c.describe_hyperparameters()
            ),
            None => errln!("hyperparameters: {}", c.describe_hyperparameters()),
        }
        let cv: Vec<String> =
            c.scheme.cross_validation.iter().map(|(i, e)| format!("{} {e:.3e}", crate::calibrate::scheme::label(*i))).collect();
        errln!(
            "scheme: {} ({}{})",
            c.scheme.label(),
            c.scheme.chosen_by,
            if cv.is_empty() { String::new() } else { format!(": held-out RMS {}", cv.join(", ")) }
        );
    }
    for w in &c.warnings {
        errln!("warning: {w}");
    }
}

/// CbD through the one calibration pipeline (`crate::calibrate`) on whatever base model the caller
/// gives (nominal, DH-calibrated, with effects), deformed as given (`--geometry nominal`): the blob
/// `cbd fit --geometry nominal` writes for that model, data and flags.
pub fn cbd_fitter(
    settings: &crate::calibrate::Settings,
) -> impl Fn(&cbd_protocol::NominalModel, &crate::data::Measurements) -> crate::Result<crate::evaluation::correction::FittedCorrection> {
    let settings = crate::calibrate::Settings { geometry: crate::calibrate::Geometry::Nominal, ..settings.clone() };
    move |nominal: &cbd_protocol::NominalModel,
          data: &crate::data::Measurements|
          -> crate::Result<crate::evaluation::correction::FittedCorrection> {
        let calibration = crate::calibrate::calibrate(nominal, data, &settings)?;
        print_calibration(&calibration, !settings.solver.verbose);
        let mut note = calibration.describe_hyperparameters();
        if let Some(e) = &calibration.evidence {
            note += &format!("; evidence {:.2} on {} rows ({:.2} s)", e.log_evidence, e.rows_used, e.seconds);
        }
        // Which member of the prior family the row used (docs/DESIGN.md §16).
        let member = if calibration.hyperparameters.configuration.is_some() { "with the configuration field" } else { "CbD's two fields" };
        note += &match &calibration.configuration {
            Some(f) => format!(
                "; prior: {member} (configuration field {} by evidence: {:.1} → {:.1}, margin {:.1})",
                if f.chosen { "chosen" } else { "not chosen" },
                f.plain_log_evidence,
                f.with_term_log_evidence,
                f.margin
            ),
            None => format!("; prior: {member}"),
        };
        note += &format!("; {} ({})", calibration.scheme.label(), calibration.scheme.chosen_by);
        for w in &calibration.warnings {
            note += &format!("; warning: {w}");
        }
        let blob = calibration.fit.blob;
        let predictor: crate::evaluation::correction::Predictor =
            Box::new(move |joints: &[f64]| crate::predict::evaluate_blob(&blob, joints).unwrap_or_else(|_| vec![f64::NAN; joints.len()]));
        Ok(crate::evaluation::correction::FittedCorrection {
            noise_sigma: Some(calibration.hyperparameters.sigma),
            ..crate::evaluation::correction::FittedCorrection::new(predictor, note)
        })
    }
}

/// A blob that does not fit the model file (or the built-in arm) it is used with: one message
/// naming both, for `eval` and `compensate`.
pub fn blob_misfit(blob: &std::path::Path, model: &ModelArgs, why: String) -> Error {
    let file = model.model.as_ref().map_or("the built-in RR arm (no --model given)".to_string(), |p| p.display().to_string());
    Error::InvalidInput(format!("{}: does not fit {file}: {why}", blob.display()))
}

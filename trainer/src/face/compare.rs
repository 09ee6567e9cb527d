//! Every peer on the same data (`cbd compare`): nominal, parametric DH calibration, kernel ridge
//! (GP) regression of the residual, Calibration by Diffeomorphisms, and the hybrids — fitted on the
//! training rows, their errors on the test rows.

use super::peers::{fitters, PeerContext, PEERS};
use super::{ArmModel, Dataset, PipelineOptions};
use crate::data::Measurements;
use crate::error::{Error, Result};
use crate::evaluation::commanded::{commanded_arm, fit_and_command, CommandedAccuracy, SimulatedArm};
use crate::evaluation::compare::{compare_inputs, compare_peers};
use crate::evaluation::peers::Peer;
use cbd_protocol::NominalModel;
use std::path::Path;

/// What a comparison is asked beyond the data: the flags of `cbd compare` but its files, and the
/// keywords of the Python package's `compare` (one set of defaults).
#[derive(Debug, Clone, clap::Args, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CompareSettings {
    /// The data come from `cbd simulate --robot <rr|six>`: add the commanded-accuracy table (true
    /// tool error of that simulated arm after each method's compensation, 1000 random reachable
    /// targets; JSON key `commanded`). Fits DH, kernel ridge and CbD again for it.
    #[arg(long)]
    pub commanded: Option<String>,
    /// CbD's hyperparameters and scheme, as in `cbd fit` (chosen by the pipeline when unset).
    #[command(flatten)]
    #[serde(flatten)]
    pub solver: PipelineOptions,
}

impl CompareSettings {
    /// `--commanded` with a registered base is refused before any fit (and before a front reads the rows).
    pub fn check(&self, arm: &ArmModel) -> Result<()> {
        if self.commanded.is_some() && arm.register_base() {
            // The commanded table sends each method's commands to the simulated arm in its own base
            // frame; a registered frame is only an estimate of where that is (1000 of 1000 targets
            // "missed" by about a metre). Refused before any fit.
            return Err(Error::InvalidInput(format!(
                "--commanded: {} declares the base unknown (`[chain] base = {{ register = true }}`), but the commanded table needs the simulated arm's own frame: compare data measured in the arm's base frame with a declared base (without --tracker-frame)",
                arm.name()
            )));
        }
        Ok(())
    }
}

/// Every method's errors side by side, and with `--commanded` the simulated arm's commanded accuracy.
pub struct Comparison {
    pub methods: crate::evaluation::compare::Comparison,
    pub commanded: Option<CommandedAccuracy>,
    /// The base registered on the training rows, when the model file declares it unknown.
    pub registration: Option<crate::parametric::base_registration::Registration>,
    /// The model file's length unit (the data are read into it).
    unit: &'static str,
}

impl Comparison {
    /// The table `cbd compare` prints.
    pub fn table(&self) -> String {
        self.methods.table(self.unit)
    }

    /// "method: note" for each method with a note (printed under the table).
    pub fn notes(&self) -> Vec<String> {
        self.methods.rows.iter().filter(|r| !r.note.is_empty()).map(|r| format!("{}: {}", r.name, r.note)).collect()
    }

    /// The commanded-accuracy table (`--commanded`).
    pub fn commanded_table(&self) -> Option<String> {
        self.commanded.as_ref().map(|c| c.table(self.unit))
    }

    /// Writes the chart of every method's test-error distribution (PNG and SVG) into `dir`; the number of files.
    pub fn write_figures(&self, dir: &Path) -> Result<usize> {
        let methods: Vec<(String, Vec<f64>)> =
            self.methods.rows.iter().filter(|r| !r.test_errors.is_empty()).map(|r| (r.name.clone(), r.test_errors.clone())).collect();
        Ok(crate::report::plots::method_comparison(dir, &methods, self.unit)?.len())
    }

    /// `cbd compare --json`'s value (one object per method under "methods").
    pub fn to_json(&self) -> serde_json::Value {
        let mut json = self.methods.to_json();
        if let Some(r) = &self.registration {
            json["registered_base"] = r.to_json();
        }
        if let Some(c) = &self.commanded {
            json["commanded"] = c.to_json();
        }
        json
    }
}

/// Compares every peer fitted on `train` on the `test` rows, both read with `arm`'s columns (it
/// must be a model file's). One function for the command and the Python package.
pub fn compare(arm: &ArmModel, train: &Dataset, test: &Dataset, settings: &CompareSettings) -> Result<Comparison> {
    settings.check(arm)?;
    let file = arm.file.as_ref().ok_or_else(|| Error::InvalidInput("a comparison needs a model file (--model)".into()))?;
    let mut pipeline = settings.solver.settings()?;
    // The table is the output here; the fits' own progress lines would drown it.
    pipeline.solver.verbose = false;
    // Each row deforms the model it is handed: `cbd` the nominal, `dh+cbd` the DH-calibrated chain.
    pipeline.geometry = crate::calibrate::Geometry::Nominal;
    let inputs = compare_inputs(file, (&train.source, train.imported.clone()), (&test.source, test.imported.clone()))?;
    let unit = arm.length_unit();
    if let Some(r) = &inputs.registration {
        errln!("{}: {}", train.source.display(), r.describe(unit));
    }
    let mut warnings = inputs.warnings;
    for (path, imported) in [(&train.source, &inputs.train), (&test.source, &inputs.test)] {
        warnings.extend(crate::data::preparation::nominal_warnings(
            &inputs.nominal,
            &imported.measurements,
            &imported.lines,
            path,
            inputs.registration.is_some(),
        )?);
    }
    for w in warnings {
        errln!("warning: {w}");
    }
    if let Some(robot) = &settings.commanded {
        commanded_arm(robot, &inputs.nominal)?;
    }
    // CbD and the hybrids fit all training rows: refuse up front what cannot fit in memory.
    let rows = &inputs.train.measurements;
    let threads = crate::memory::check_fit_of(
        &train.source,
        rows.len(),
        rows.task_dim,
        "use fewer training rows (cbd fit --max-rows N fits an evenly spaced subset)",
    )?;
    pipeline.solver.threads = threads;
    let context = PeerContext { settings: pipeline.clone(), search: Default::default() };
    let mut methods = crate::memory::on_workers(threads, || {
        let fitters = fitters(PEERS, &context);
        let peers: Vec<Peer> = fitters.iter().map(|f| f.peer()).collect();
        compare_peers(&inputs.nominal, rows, &inputs.test.measurements, &peers)
    });
    // The row `cbd fit` writes by default, and the noise floor from the σ that row's fit assumed
    // (what `cbd fit` records in the blob), else its hypothesis' evidence.
    let choice = crate::memory::on_workers(threads, || crate::calibrate::geometry::geometry_choice(&inputs.nominal, rows, &pipeline))?;
    methods.default_fit = Some(choice);
    let written = methods.written_by_fit().and_then(|name| methods.rows.iter().find(|r| r.name == name));
    methods.noise_floor = written.and_then(|r| noise_floor(r.noise_sigma, &r.name, &pipeline, rows.task_dim));
    for w in methods.warnings() {
        errln!("warning: {w}");
    }
    let commanded = match &settings.commanded {
        Some(robot) => Some(crate::memory::on_workers(threads, || commanded_peers(robot, &inputs.nominal, rows, &context))?),
        None => None,
    };
    Ok(Comparison { methods, commanded, registration: inputs.registration, unit })
}

/// The floor of a table's rows: σ of the `row` `cbd fit` writes (its evidence's, on the training
/// rows), or the hand-given `--sigma`.
fn noise_floor(
    sigma: Option<f64>,
    row: &str,
    settings: &crate::calibrate::Settings,
    m: usize,
) -> Option<crate::report::noise_floor::NoiseFloor> {
    use crate::report::noise_floor::NoiseFloor;
    match (sigma, settings.overrides.sigma) {
        (_, Some(s)) => Some(NoiseFloor::new(s, m, "--sigma as given")),
        (Some(s), None) => Some(NoiseFloor::new(s, m, format!("CbD's evidence on the training rows, {row}"))),
        _ => None,
    }
}

/// `cbd compare --commanded <robot>`: the accuracy of the arm `cbd simulate --robot <robot>`
/// measures commanded by each peer of the list, fitted again for it with `context`.
fn commanded_peers(robot: &str, nominal: &NominalModel, train: &Measurements, context: &PeerContext) -> Result<CommandedAccuracy> {
    let arm = commanded_arm(robot, nominal)?;
    if let Some(note) = not_the_arms_data(robot, &arm, nominal, train) {
        errln!("warning: {note}");
    }
    let fitters = fitters(PEERS, context);
    let peers: Vec<Peer> = fitters.iter().map(|f| f.peer()).collect();
    let command = crate::evaluation::commanded_pose::commander_for(nominal);
    fit_and_command(&arm, nominal, train, &peers, command, 1000, 15)
}

/// Why the training rows were not measured on the simulated arm `robot` (`cbd simulate --robot
/// robot`), when they were not: that arm's noise-free positions at the rows' joints are no closer
/// to the measured ones than the nominal model's. The commanded table is then that arm's, not the
/// data's robot's — said, since its figures would read as the user's robot's.
fn not_the_arms_data(robot: &str, arm: &SimulatedArm, nominal: &NominalModel, train: &Measurements) -> Option<String> {
    let m = train.task_dim;
    let nominal_positions = crate::nominal::positions(nominal, &train.joints, m);
    let (mut to_arm, mut to_nominal) = (0.0, 0.0);
    for i in 0..train.len() {
        let measured = train.position(i);
        let at = arm.true_position(train.joints(i));
        to_arm += measured.iter().zip(&at).map(|(a, b)| (a - b) * (a - b)).sum::<f64>();
        to_nominal += measured.iter().zip(&nominal_positions[i * m..(i + 1) * m]).map(|(a, b)| (a - b) * (a - b)).sum::<f64>();
    }
    let n = train.len().max(1) as f64;
    let (to_arm, to_nominal) = ((to_arm / n).sqrt(), (to_nominal / n).sqrt());
    (to_arm.is_finite() && to_arm > 0.5 * to_nominal).then(|| {
        format!(
            "--commanded {robot}: the training rows are {} from the simulated arm `cbd simulate --robot {robot}` measures (RMS at their joints), no closer than the nominal model ({}): they were not measured on that arm, and the commanded table below is that arm's accuracy, not your robot's",
            crate::error::number(to_arm),
            crate::error::number(to_nominal)
        )
    })
}

/// The commanded-accuracy table with the peers wired as `cbd compare --commanded` wires them.
#[cfg(test)]
mod provenance_tests {
    use super::*;

    /// Issue 51 class 4: `--commanded six` on rows from another arm is explained; on the arm's own
    /// rows it is not.
    #[test]
    fn rows_from_another_arm_are_noted() {
        let arm = SimulatedArm::named("six").unwrap();
        let SimulatedArm::Six(robot) = &arm else { unreachable!() };
        let own = robot.measure(&crate::simulate::six_joint::random_configurations(40, 3), 4);
        assert_eq!(not_the_arms_data("six", &arm, &robot.nominal, &own), None);
        let other = crate::simulate::six_joint::SixJointRobot::ur5_like(9);
        let foreign = other.measure(&crate::simulate::six_joint::random_configurations(40, 3), 4);
        let note = not_the_arms_data("six", &arm, &robot.nominal, &foreign).expect("a note");
        assert!(note.contains("--commanded six: the training rows are") && note.contains("not your robot's"), "{note}");
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::evaluation::commanded::{commanded_accuracy, SimulatedArm};

    /// Every peer of the list fitted on `train` and commanded (CbD with the default settings, quiet).
    fn command_peers(
        arm: &SimulatedArm,
        nominal: &NominalModel,
        train: &Measurements,
        command: crate::evaluation::commanded::Commander,
        count: usize,
    ) -> CommandedAccuracy {
        let context = PeerContext { settings: crate::calibrate::Settings::default(), search: Default::default() };
        let fitters = fitters(PEERS, &context);
        let peers: Vec<Peer> = fitters.iter().map(|f| f.peer()).collect();
        fit_and_command(arm, nominal, train, &peers, command, count, 7).unwrap()
    }

    /// Issue 15's criteria for CbD's row `best` (cbd on the RR arm, dh+cbd on the six-joint arm,
    /// the rows `cbd compare` ranks first there): commanded error within 1.2× its forward error,
    /// ahead of DH-only compensation.
    fn check(c: &CommandedAccuracy, unit: &str, best: &str) {
        errln!("{}", c.table(unit));
        let row = |n: &str| c.rows.iter().find(|r| r.name == n).unwrap();
        let get = |n: &str| row(n).stats.mean;
        for r in c.rows.iter().filter(|r| r.name.contains("cbd")) {
            errln!("{}: compensation residual |k1(q) - x| {:?}", r.name, r.residual.unwrap());
            let forward = r.forward.unwrap().mean;
            assert!(r.stats.mean <= 1.2 * forward, "{} commanded {} vs forward {forward}", r.name, r.stats.mean);
        }
        assert!(get(best) < get("dh"), "{best} {} vs dh {}", get(best), get("dh"));
        assert!(get("dh") < get("nominal"));
        let json = c.to_json();
        // Every forward method of `cbd compare` has a commanded row.
        for name in ["nominal", "dh", "krr", "dh+krr", "cbd"] {
            assert!(json["methods"][name]["mean"].is_number(), "{name}");
        }
    }

    #[test]
    fn commanded_accuracy_on_the_simulated_rr_arm() {
        let arm = SimulatedArm::named("rr").unwrap();
        let SimulatedArm::Rr(real) = &arm else { unreachable!() };
        let train = real.measure(&crate::simulate::configurations(crate::simulate::Sampling::Grid { per_axis: 16 }, 2));
        let nominal = crate::simulate::rr::nominal();
        let c = command_peers(&arm, &nominal, &train, commanded_accuracy, 1000);
        check(&c, "m", "cbd");
    }

    #[test]
    fn commanded_accuracy_on_the_simulated_six_joint_arm() {
        let arm = SimulatedArm::named("six").unwrap();
        let SimulatedArm::Six(robot) = &arm else { unreachable!() };
        let train = robot.measure(&crate::simulate::six_joint::random_configurations(250, 22), 23);
        let c = command_peers(&arm, &robot.nominal, &train, commanded_accuracy, 1000);
        check(&c, "mm", "dh+cbd");
    }

    /// The six-joint arm measured at `points` (250 poses, each point on the real chain moved to it,
    /// noise per point, rows pose-major) and its nominal model naming those points.
    fn six_arm_at_points(points: &[[f64; 3]]) -> (SimulatedArm, NominalModel, Measurements) {
        use crate::nominal::tool_points::point_chain;
        let arm = SimulatedArm::named("six").unwrap();
        let SimulatedArm::Six(robot) = &arm else { unreachable!() };
        let joints = crate::simulate::six_joint::random_configurations(250, 22);
        let per_point: Vec<Measurements> = points
            .iter()
            .enumerate()
            .map(|(j, p)| {
                let mut moved = (**robot).clone();
                moved.real = point_chain(&robot.real, *p);
                moved.measure(&joints, 23 + j as u64)
            })
            .collect();
        let mut train = Measurements::with_points(6, 3, points.len());
        for k in 0..joints.len() / 6 {
            for m in &per_point {
                train.push(m.joints(k), m.position(k));
            }
        }
        let NominalModel::DhChain(mut chain) = robot.nominal.clone() else { unreachable!() };
        chain.tool_points = heapless::Vec::from_slice(points).unwrap();
        (arm, NominalModel::DhChain(chain), train)
    }

    /// Two tool points determine no orientation: the table commands tool point 1's position (here
    /// off the tool origin, so that commanding the origin would show), and says so.
    #[test]
    fn commanded_point_one_with_two_tool_points() {
        let (arm, nominal, train) = six_arm_at_points(&[[20.0, 0.0, 10.0], [100.0, 0.0, 0.0]]);
        let command = crate::evaluation::commanded_pose::commander_for(&nominal);
        let c = command_peers(&arm, &nominal, &train, command, 300);
        assert!(c.target.contains("tool point 1"), "{}", c.target);
        assert!(c.rows.iter().all(|r| r.orientation_deg.is_none()));
        check(&c, "mm", "dh+cbd");
    }

    /// Issue 26 item 1: a model with three tool points on the six-joint arm commands poses — every
    /// method through pose compensation (CbD: `Calibrator::compensate_pose`), the true tool frame's
    /// origin and orientation reported; dh+cbd within 1.2× its forward error in both, ahead of DH.
    #[test]
    fn commanded_poses_on_the_simulated_six_joint_arm_with_three_tool_points() {
        let (arm, nominal, train) = six_arm_at_points(&[[0.0, 0.0, 0.0], [100.0, 0.0, 0.0], [50.0, 86.60254037844386, 0.0]]);
        let command = crate::evaluation::commanded_pose::commander_for(&nominal);
        let c = command_peers(&arm, &nominal, &train, command, 300);
        errln!("{}", c.table("mm"));
        assert!(c.target.contains("pose"), "{}", c.target);
        let row = |n: &str| c.rows.iter().find(|r| r.name == n).unwrap_or_else(|| panic!("no row {n}"));
        for name in ["nominal", "dh", "krr", "dh+krr", "cbd", "dh+cbd"] {
            assert!(row(name).orientation_deg.is_some_and(|o| o.mean.is_finite()), "{name}: orientation");
        }
        let best = row("dh+cbd");
        let (forward, forward_angle) = (best.forward.unwrap().mean, best.forward_orientation_deg.unwrap().mean);
        let (position, angle) = (best.stats.mean, best.orientation_deg.unwrap().mean);
        assert!(
            position <= 1.2 * forward && angle <= 1.2 * forward_angle,
            "dh+cbd {position} mm {angle}° vs forward {forward} {forward_angle}"
        );
        let dh = row("dh");
        assert!(position < dh.stats.mean && angle < dh.orientation_deg.unwrap().mean, "dh+cbd against dh");
        assert!(dh.stats.mean < row("nominal").stats.mean);
        let json = c.to_json();
        assert!(json["methods"]["dh+cbd"]["orientation_deg"]["mean"].is_number(), "{json}");
    }
}

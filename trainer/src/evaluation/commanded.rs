//! Commanded accuracy: where the simulated "real" arm's tool goes when each method turns a
//! Cartesian target into a joint command. The true tool error |real(q) − x| of 1000 random
//! reachable targets x = real(q*) (q* random configurations of the simulator's range), for
//! (a) the nominal model's inverse kinematics, (b) DH-calibrated compensation (the inverse
//! kinematics of the calibrated chain; for the planar arm the DH calibration of its planar form:
//! link lengths, joint offsets, base position and yaw), then each peer of the caller's list
//! ([`fit_and_command`], [`Command`]): a correction of the positions (kernel ridge) by pose redefinition
//! (command the nominal IK of x', x' ← x' + x − krr(q), five times), its `dh+` row the same on the
//! DH-calibrated chain with the correction fitted on its residual (for the planar arm its
//! DH form); a blob (CbD) by its own compensation (`Calibrator::compensate` from the nominal IK). Every method starts from the same hint per
//! target: q* moved by up to 0.05 rad per joint (a controller's previous command).

use super::correction::Predictor;
use super::peers::{Command, Peer};
use crate::data::Measurements;
use crate::error::Error;
use crate::nominal::planar::as_planar_in_frame;
use crate::parametric::{calibrate_dh, DhCalibrationOptions};
use crate::report::stats::ErrorStats;
use crate::simulate::{rr::RealRr, six_joint::SixJointRobot};
use cbd_protocol::NominalModel;
use cbd_runtime::internals::inverse_kinematics::{nominal_position, planar};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Steps of every nominal inverse kinematics (closed form first where there is one).
const NOMINAL_IK_ITERATIONS: usize = 8;
/// Pose-redefinition rounds of kernel-ridge compensation.
const POSE_REDEFINITION_ROUNDS: usize = 5;
/// Largest random change of each joint from q* to the hint (radians).
const HINT_PERTURBATION: f64 = 0.05;

/// A simulated arm whose true tool position is known.
#[derive(Debug, Clone)]
pub enum SimulatedArm {
    /// `cbd simulate --robot rr` (no injected effects).
    Rr(RealRr),
    /// `cbd simulate --robot six` (no injected effects).
    Six(Box<SixJointRobot>),
}

impl SimulatedArm {
    /// The arm `cbd simulate --robot <name>` measures: `rr` or `six`.
    pub fn named(name: &str) -> crate::Result<SimulatedArm> {
        match name {
            "rr" => Ok(SimulatedArm::Rr(RealRr::default())),
            "six" => Ok(SimulatedArm::Six(Box::new(SixJointRobot::ur5_like(1)))),
            other => Err(Error::InvalidInput(format!("unknown simulated robot `{other}` (expected rr or six)"))),
        }
    }
    /// Noise-free tool position when commanded `q`.
    pub fn true_position(&self, q: &[f64]) -> Vec<f64> {
        match self {
            SimulatedArm::Rr(arm) => arm.position(q).to_vec(),
            SimulatedArm::Six(robot) => robot.true_position(q).to_vec(),
        }
    }
    /// The six-joint arm's true tool frame when commanded `q` (its real chain at the joints gravity
    /// deflects `q` to, the frame whose points `cbd simulate --tool-points` measures); `None` for
    /// the planar arm.
    pub fn true_frame(&self, q: &[f64]) -> Option<crate::nominal::Frame> {
        match self {
            SimulatedArm::Rr(_) => None,
            SimulatedArm::Six(robot) => {
                let walk = cbd_runtime::internals::kinematics::rigid::dh_walk(&robot.real, &robot.deflected(q));
                Some(crate::nominal::Frame::new(walk.tool_rotation, walk.tool))
            }
        }
    }
    /// Noise-free position of tool point `point` (offset in the tool frame) when commanded `q`;
    /// `None` is the tool origin ([`SimulatedArm::true_position`]).
    pub fn true_point(&self, q: &[f64], point: Option<[f64; 3]>) -> Vec<f64> {
        match (point, self.true_frame(q)) {
            (Some(p), Some(frame)) => frame.apply(p).to_vec(),
            _ => self.true_position(q),
        }
    }
    /// `count` random configurations in the simulator's range.
    pub fn random_configurations(&self, count: usize, seed: u64) -> Vec<f64> {
        match self {
            SimulatedArm::Rr(_) => crate::simulate::configurations(crate::simulate::Sampling::Uniform { count, seed }, 2),
            SimulatedArm::Six(_) => crate::simulate::six_joint::random_configurations(count, seed),
        }
    }
    pub fn n_joints(&self) -> usize {
        match self {
            SimulatedArm::Rr(_) => 2,
            SimulatedArm::Six(_) => 6,
        }
    }
}

/// The planar arm's parametric calibration, z = b + l1 e^{i (q1 + o1)} + l2 e^{i (q1 + q2 + o2)}
/// (complex base b, link lengths, link angle offsets): DH calibration of the arm's planar DH form
/// ([`calibrate_dh`] with `planar_as_dh`: lengths, joint offsets, base x, y and yaw), read as a
/// planar chain in its frame ([`as_planar_in_frame`]) for the closed-form inverse.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlanarCalibration {
    pub base: [f64; 2],
    pub lengths: [f64; 2],
    /// Angle of link 1 is q1 + offsets[0], of link 2 q1 + q2 + offsets[1].
    pub offsets: [f64; 2],
}

impl PlanarCalibration {
    /// `None` unless `nominal` is a two-link planar arm whose calibration succeeds.
    pub fn fit(nominal: &NominalModel, data: &Measurements) -> Option<PlanarCalibration> {
        if !matches!(nominal, NominalModel::PlanarChain { lengths, .. } if lengths.len() == 2) {
            return None;
        }
        let options = DhCalibrationOptions { planar_as_dh: true, ..DhCalibrationOptions::default() };
        let fit = calibrate_dh(nominal, data, &options).ok()?;
        let (chain, frame) = as_planar_in_frame(&fit.model)?;
        let NominalModel::PlanarChain { lengths, .. } = chain else { return None };
        // Link k's angle: yaw + Σ_{j ≤ k} (q_j + θ_offset_j).
        let o1 = frame.yaw + frame.offsets[0];
        Some(PlanarCalibration { base: frame.base, lengths: [lengths[0], lengths[1]], offsets: [o1, o1 + frame.offsets[1]] })
    }

    pub fn position(&self, q: &[f64]) -> [f64; 2] {
        let (a1, a2) = (q[0] + self.offsets[0], q[0] + q[1] + self.offsets[1]);
        [
            self.base[0] + self.lengths[0] * a1.cos() + self.lengths[1] * a2.cos(),
            self.base[1] + self.lengths[0] * a1.sin() + self.lengths[1] * a2.sin(),
        ]
    }

    /// Closed-form inverse ([`planar::two_link`] on x − b, offsets removed), the elbow nearer
    /// `hint`; `None` when out of reach.
    pub fn inverse(&self, target: &[f64], hint: &[f64]) -> Option<[f64; 2]> {
        let w = [target[0] - self.base[0], target[1] - self.base[1]];
        let [l1, l2] = self.lengths;
        let mut best: Option<(f64, [f64; 2])> = None;
        for sol in planar::two_link_both(l1, l2, w)? {
            // Link angles θ1 = q1 + o1, θ1 + θ2 = q1 + q2 + o2.
            let mut q = [sol[0] - self.offsets[0], sol[1] + self.offsets[0] - self.offsets[1]];
            let mut d = 0.0;
            for (qi, h) in q.iter_mut().zip(hint) {
                *qi += cbd_runtime::internals::inverse_kinematics::nearest_turn(h - *qi);
                d += (*qi - h).powi(2);
            }
            if best.map(|(bd, _)| d < bd).unwrap_or(true) {
                best = Some((d, q));
            }
        }
        best.map(|(_, q)| q)
    }
}

/// The fitted corrections the commanded table compares.
pub struct Fitted<'a> {
    pub nominal: &'a NominalModel,
    /// DH-calibrated chain (six-joint) — or `None`.
    pub dh: Option<&'a NominalModel>,
    /// Planar parametric calibration (RR) — or `None`.
    pub planar: Option<PlanarCalibration>,
    /// The peers' rows after `nominal` and `dh`, in the list's order.
    pub peers: Vec<FittedPeer>,
}

/// One peer's row of the commanded table, fitted.
pub struct FittedPeer {
    /// `krr`, `dh+krr`, `cbd`, `dh+cbd`, …
    pub name: String,
    pub command: FittedCommand,
}

/// A fitted peer as the table commands it ([`Command`]).
pub enum FittedCommand {
    /// Pose redefinition through `predict` (corrected positions) on `chain`: `None` the nominal
    /// model, else a calibrated chain (for the planar arm its DH form, commanded in closed form).
    Redefine { chain: Option<Box<NominalModel>>, predict: Predictor },
    /// The blob's own compensation.
    Compensate { blob: Vec<u8> },
}

/// One method's true tool errors after commanding.
#[derive(Debug, Clone, PartialEq)]
pub struct CommandedRow {
    /// `nominal`, `dh`, then the peers' rows (`krr`, `dh+krr`, `cbd`, `dh+cbd`).
    pub name: String,
    pub stats: ErrorStats,
    /// For CbD rows: |k1(q*) − real(q*)| over the targets' configurations, its forward error there.
    pub forward: Option<ErrorStats>,
    /// Targets the method's own model says it did not reach (its IK out of reach, or for CbD the
    /// `reached` flag false).
    pub not_reached: usize,
    /// For CbD rows: |k1(q) − x| at the commands, the compensation's own residual.
    pub residual: Option<ErrorStats>,
    /// Pose targets: the true tool frame's orientation error (degrees) after the command.
    pub orientation_deg: Option<ErrorStats>,
    /// Pose targets, CbD rows: the calibrated frame's orientation error at q* (degrees).
    pub forward_orientation_deg: Option<ErrorStats>,
}

/// The commanded-accuracy table.
#[derive(Debug, Clone, PartialEq)]
pub struct CommandedAccuracy {
    pub targets: usize,
    pub rows: Vec<CommandedRow>,
    /// What the targets are: `tool position`, `tool pose`, or tool point 1's position.
    pub target: String,
}

impl CommandedAccuracy {
    /// `{"targets": N, "target": what, "methods": {name: {mean, median, p99, max, not_reached,
    /// forward_mean?, orientation_deg?: {mean, median, p99, max}, forward_orientation_mean_deg?}}}`.
    pub fn to_json(&self) -> serde_json::Value {
        use serde_json::json;
        let mut methods = serde_json::Map::new();
        for r in &self.rows {
            let mut row = json!({"mean": r.stats.mean, "median": r.stats.median, "p99": r.stats.p99, "max": r.stats.max, "not_reached": r.not_reached});
            if let Some(f) = &r.forward {
                row["forward_mean"] = json!(f.mean);
                row["forward_median"] = json!(f.median);
            }
            if let Some(r) = &r.residual {
                row["residual_median"] = json!(r.median);
                row["residual_p99"] = json!(r.p99);
                row["residual_max"] = json!(r.max);
            }
            if let Some(o) = &r.orientation_deg {
                row["orientation_deg"] = json!({"mean": o.mean, "median": o.median, "p99": o.p99, "max": o.max});
            }
            if let Some(o) = &r.forward_orientation_deg {
                row["forward_orientation_mean_deg"] = json!(o.mean);
            }
            methods.insert(r.name.clone(), row);
        }
        json!({"targets": self.targets, "target": self.target, "methods": methods})
    }

    pub fn table(&self, unit: &str) -> String {
        let mut out = format!(
            "commanded accuracy ({} targets): true tool error ({unit}) at {} random reachable targets\n{:10} {:>12} {:>12} {:>12} {:>12} {:>12} {:>14}\n",
            self.target, self.targets, "method", "mean", "median", "p99", "max", "not reached", "forward mean"
        );
        for r in &self.rows {
            let forward = r.forward.map(|f| format!("{:.4e}", f.mean)).unwrap_or_default();
            out += &format!(
                "{:10} {:>12.4e} {:>12.4e} {:>12.4e} {:>12.4e} {:>12} {:>14}\n",
                r.name, r.stats.mean, r.stats.median, r.stats.p99, r.stats.max, r.not_reached, forward
            );
        }
        if self.rows.iter().any(|r| r.orientation_deg.is_some()) {
            out += &format!(
                "orientation of the true tool frame (degrees):\n{:10} {:>12} {:>12} {:>12} {:>12} {:>14}\n",
                "method", "mean", "median", "p99", "max", "forward mean"
            );
            for r in &self.rows {
                let Some(o) = &r.orientation_deg else { continue };
                let forward = r.forward_orientation_deg.map(|f| format!("{:.4e}", f.mean)).unwrap_or_default();
                out += &format!("{:10} {:>12.4e} {:>12.4e} {:>12.4e} {:>12.4e} {:>14}\n", r.name, o.mean, o.median, o.p99, o.max, forward);
            }
        }
        out
    }
}

fn distance(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum::<f64>().sqrt()
}

/// The table for `count` targets drawn from `seed` (see the module doc).
/// Position targets; with several tool points, tool point 1's position (the point position-only
/// compensation commands; pose targets: `commanded_pose`, chosen by `commanded_pose::commander_for`).
pub fn commanded_accuracy(arm: &SimulatedArm, fitted: &Fitted<'_>, count: usize, seed: u64) -> crate::Result<CommandedAccuracy> {
    let n = arm.n_joints();
    let nominal = fitted.nominal;
    if nominal.n_joints() != n {
        return Err(Error::InvalidInput(format!("the model has {} joints, the simulated arm {n}", nominal.n_joints())));
    }
    // Several tool points without an orientation to command: tool point 1, through each model's
    // chain moved to it (the runtime's position-only compensation commands point 1 too).
    let point = (nominal.tool_point_count() > 1).then(|| nominal.tool_point(0)).flatten();
    let at_point = |model: &NominalModel| match point {
        Some(_) => cbd_runtime::internals::kinematics::tool_point::at_tool_point(model, 0).unwrap_or_else(|| model.clone()),
        None => model.clone(),
    };
    let target = match point {
        Some(_) => "tool point 1 position (pose compensation needs at least 6 joints and 3 tool points off a line)",
        None => "tool position",
    };
    let (nominal_at, dh_at) = (at_point(nominal), fitted.dh.map(at_point));
    // The calibrated chains the corrections' `dh+` rows command, moved to the point.
    let chains_at: Vec<Option<NominalModel>> = fitted
        .peers
        .iter()
        .map(|p| match &p.command {
            FittedCommand::Redefine { chain: Some(chain), .. } => Some(at_point(chain)),
            _ => None,
        })
        .collect();
    let nominal = &nominal_at;
    let configurations = arm.random_configurations(count, seed);
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0xc0ffee);
    let scale = {
        let targets: Vec<f64> = configurations.chunks_exact(n).flat_map(|q| arm.true_point(q, point)).collect();
        let m = nominal.task_dim();
        (targets.chunks_exact(m).map(|t| t.iter().map(|v| v * v).sum::<f64>()).sum::<f64>() / count.max(1) as f64).sqrt().max(1e-12)
    };
    let mut storages: Vec<Vec<f64>> = Vec::new();
    let mut models = Vec::new();
    for p in &fitted.peers {
        let FittedCommand::Compensate { blob } = &p.command else { continue };
        let name = p.name.as_str();
        let model = cbd_protocol::decode(blob).map_err(|e| Error::from(e).context(name))?;
        storages.push(vec![0.0; cbd_runtime::storage_len_for(&model)]);
        models.push((name, model));
    }
    let mut calibrators = Vec::new();
    for ((name, model), storage) in models.into_iter().zip(storages.iter_mut()) {
        calibrators
            .push((name, cbd_runtime::Calibrator::from_model(model, storage).map_err(|e| Error::from(e).context(name.to_string()))?));
    }
    let mut names = vec!["nominal", "dh"];
    names.extend(fitted.peers.iter().map(|p| p.name.as_str()));
    let mut errors: Vec<Vec<f64>> = vec![Vec::new(); names.len()];
    let mut not_reached = vec![0usize; names.len()];
    let mut forward: Vec<Vec<f64>> = vec![Vec::new(); names.len()];
    let mut residuals: Vec<Vec<f64>> = vec![Vec::new(); names.len()];
    let nominal_ik = |model: &NominalModel, x: &[f64], hint: &[f64]| -> (Vec<f64>, bool) {
        let mut q = vec![0.0; n];
        match nominal_position(model, x, hint, &mut q, NOMINAL_IK_ITERATIONS, scale) {
            Some(s) => (q, s.residual <= 1e-9 * scale),
            None => (hint.to_vec(), false),
        }
    };
    for q_star in configurations.chunks_exact(n) {
        let x = arm.true_point(q_star, point);
        let hint: Vec<f64> = q_star.iter().map(|q| q + rng.gen_range(-HINT_PERTURBATION..HINT_PERTURBATION)).collect();
        let mut record = |k: usize, q: &[f64], reached: bool| {
            errors[k].push(distance(&arm.true_point(q, point), &x));
            if !reached {
                not_reached[k] += 1;
            }
        };
        // (a) nominal inverse kinematics.
        let (q_nominal, ok) = nominal_ik(nominal, &x, &hint);
        record(0, &q_nominal, ok);
        // (b) DH-calibrated compensation.
        if let Some(dh) = &dh_at {
            let (q, ok) = nominal_ik(dh, &x, &hint);
            record(1, &q, ok);
        } else if let Some(p) = &fitted.planar {
            match p.inverse(&x, &hint) {
                Some(q) => record(1, &q, true),
                None => record(1, &q_nominal, false),
            }
        }
        // (c) a correction (kernel ridge) by pose redefinition: x' ← x' + (x − krr(q)), on the
        // nominal model or (its `dh+` row) on the DH-calibrated chain.
        let pose_redefinition = |krr: &Predictor, ik: &dyn Fn(&[f64], &[f64]) -> (Vec<f64>, bool)| {
            let mut shifted = x.clone();
            let mut q = q_nominal.clone();
            let mut ok = true;
            for _ in 0..POSE_REDEFINITION_ROUNDS {
                (q, ok) = ik(&shifted, &q);
                let predicted = krr(&q);
                for (s, (target, p)) in shifted.iter_mut().zip(x.iter().zip(predicted)) {
                    *s += target - p;
                }
            }
            (q, ok)
        };
        // (c, d) the peers: pose redefinition through a correction, or a blob's compensation.
        let mut calibrator = calibrators.iter_mut();
        for (i, p) in fitted.peers.iter().enumerate() {
            let k = 2 + i;
            match &p.command {
                FittedCommand::Redefine { chain: None, predict } => {
                    let (q, ok) = pose_redefinition(predict, &|target, hint| nominal_ik(nominal, target, hint));
                    record(k, &q, ok);
                }
                FittedCommand::Redefine { chain: Some(_), predict } => {
                    let model = chains_at[i].as_ref().ok_or_else(|| Error::Internal(format!("{}: no chain", p.name)))?;
                    // The chain's own inverse: the planar arm's closed form in its frame, else the DH chain's.
                    let (q, ok) = match &fitted.planar {
                        Some(planar) if fitted.dh.is_none() => {
                            pose_redefinition(predict, &|target, hint| match planar.inverse(target, hint) {
                                Some(q) => (q.to_vec(), true),
                                None => (hint.to_vec(), false),
                            })
                        }
                        _ => pose_redefinition(predict, &|target, hint| nominal_ik(model, target, hint)),
                    };
                    record(k, &q, ok);
                }
                FittedCommand::Compensate { .. } => {
                    // From the nominal IK.
                    let (name, cal) = calibrator.next().ok_or_else(|| Error::Internal(format!("{}: no calibrator", p.name)))?;
                    let mut q = vec![0.0; n];
                    let c = cal.compensate(&x, &q_nominal, &mut q).map_err(|e| Error::from(e).context(format!("{name}: compensate")))?;
                    record(k, &q, c.reached);
                    residuals[k].push(c.residual);
                    let e = cal.evaluate(q_star).map_err(|e| Error::from(e).context(format!("{name}: evaluate")))?;
                    forward[k].push(distance(&e.position().iter().copied().collect::<Vec<_>>(), &x));
                }
            }
        }
    }
    let rows = names
        .iter()
        .zip(errors.iter().zip(not_reached).zip(forward.iter().zip(&residuals)))
        .filter(|(_, ((e, _), _))| !e.is_empty())
        .map(|(name, ((e, nr), (f, r)))| CommandedRow {
            name: name.to_string(),
            stats: ErrorStats::of_errors(e),
            not_reached: nr,
            forward: (!f.is_empty()).then(|| ErrorStats::of_errors(f)),
            residual: (!r.is_empty()).then(|| ErrorStats::of_errors(r)),
            orientation_deg: None,
            forward_orientation_deg: None,
        })
        .collect();
    Ok(CommandedAccuracy { targets: count, rows, target: target.into() })
}

/// The table of fitted methods for `count` targets drawn from `seed`: [`commanded_accuracy`] or
/// the pose table (`commanded_pose::commander_for` chooses).
pub type Commander = fn(&SimulatedArm, &Fitted<'_>, usize, u64) -> crate::Result<CommandedAccuracy>;

/// Fits every method on `train` — DH or the planar parametric fit, then each of `peers` with a
/// [`Command`] on the nominal model and, when [`Peer::on_dh`], on the DH-calibrated chain (as `cbd
/// compare`: a correction's on the DH fit, for the planar arm its DH form; a blob's on a DH chain
/// only) — and runs `command` ([`commanded_accuracy`] or the pose table). A correction that fails
/// has no row; a blob that fails is the error.
pub fn fit_and_command(
    arm: &SimulatedArm,
    nominal: &NominalModel,
    train: &Measurements,
    peers: &[Peer<'_>],
    command: Commander,
    count: usize,
    seed: u64,
) -> crate::Result<CommandedAccuracy> {
    let dh = match nominal {
        NominalModel::DhChain(_) => calibrate_dh(nominal, train, &DhCalibrationOptions::default()).ok().map(|f| f.model),
        NominalModel::PlanarChain { .. } => None,
    };
    let planar = PlanarCalibration::fit(nominal, train);
    // The chain `cbd compare`'s dh+krr row corrects: the DH fit, planar arms in their DH form.
    let dh_for_corrections = match &dh {
        Some(model) => Some(model.clone()),
        None => calibrate_dh(nominal, train, &DhCalibrationOptions { planar_as_dh: true, ..DhCalibrationOptions::default() })
            .ok()
            .map(|f| f.model),
    };
    let mut rows = Vec::new();
    for peer in peers {
        let row = |name: String, command: FittedCommand| FittedPeer { name, command };
        match peer.command {
            None => {}
            Some(Command::PoseRedefinition) => {
                if let Ok(f) = peer.fit_on_nominal(nominal, train) {
                    rows.push(row(peer.name.to_string(), FittedCommand::Redefine { chain: None, predict: f.predict }));
                }
                if let (true, Some(chain)) = (peer.on_dh, &dh_for_corrections) {
                    if let Ok(f) = peer.fit_on_chain(chain, train) {
                        rows.push(row(
                            peer.dh_name(),
                            FittedCommand::Redefine { chain: Some(Box::new(chain.clone())), predict: f.predict },
                        ));
                    }
                }
            }
            Some(Command::Compensate(fit)) => {
                rows.push(row(peer.name.to_string(), FittedCommand::Compensate { blob: fit(nominal, train)? }));
                if let (true, Some(chain)) = (peer.on_dh, &dh) {
                    rows.push(row(peer.dh_name(), FittedCommand::Compensate { blob: fit(chain, train)? }));
                }
            }
        }
    }
    let fitted = Fitted { nominal, dh: dh.as_ref(), planar, peers: rows };
    command(arm, &fitted, count, seed)
}

/// The simulated arm `--commanded robot` names, checked against the model file's arm: `compare`
/// calls it before any fit (an unknown name was refused only after all six fits).
pub fn commanded_arm(robot: &str, nominal: &NominalModel) -> crate::Result<SimulatedArm> {
    let arm = SimulatedArm::named(robot).map_err(|e| e.context("--commanded"))?;
    if arm.n_joints() != nominal.n_joints() {
        return Err(Error::InvalidInput(format!(
            "--commanded {robot}: that arm has {} joints, the model file's {}",
            arm.n_joints(),
            nominal.n_joints()
        )));
    }
    Ok(arm)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_planar_parametric_fit_recovers_an_exact_planar_arm() {
        let truth = PlanarCalibration { base: [0.03, -0.02], lengths: [1.09, 0.46], offsets: [0.01, -0.02] };
        let joints = crate::simulate::configurations(crate::simulate::Sampling::Uniform { count: 50, seed: 3 }, 2);
        let mut data = Measurements::new(2, 2);
        for q in joints.chunks_exact(2) {
            data.push(q, &truth.position(q));
        }
        let nominal = NominalModel::planar(&[1.0, 0.5]).unwrap();
        let fit = PlanarCalibration::fit(&nominal, &data).unwrap();
        for (a, b) in [fit.base, fit.lengths, fit.offsets].iter().flatten().zip([truth.base, truth.lengths, truth.offsets].iter().flatten())
        {
            assert!((a - b).abs() < 1e-12, "{fit:?}");
        }
        let q = fit.inverse(&truth.position(&[0.7, -1.2]), &[0.6, -1.0]).unwrap();
        assert!((q[0] - 0.7).abs() < 1e-12 && (q[1] + 1.2).abs() < 1e-12, "{q:?}");
    }
}

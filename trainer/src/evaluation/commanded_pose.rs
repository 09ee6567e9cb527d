//! Commanded accuracy for pose targets (issue 26 item 1): a model with tool points that determine
//! an orientation, on an arm of at least six joints. The target is the simulated arm's true tool
//! frame x* = (t*, R*) at a random configuration q*; each method turns it into a joint command and
//! the table reports where the arm's true tool frame goes: the origin's miss |t(q) − t*| and the
//! orientation's angle |log(R* R(q)ᵀ)| in degrees, as the forward table reports a pose.
//!
//! (a) nominal: the nominal pose inverse kinematics (`cbd_runtime::internals::compensate_pose::nominal_pose_inverse`:
//! the UR closed form nearest the hint, else damped Gauss–Newton on the tool frame); (b) DH: the
//! same on the DH-calibrated chain from (a)'s command; (c, c') kernel ridge by pose redefinition on
//! the tool points, y'_j ← y'_j + y*_j − krr_j(q) (y*_j = R* p_j + t*), the frame fitted to y'
//! commanded through (a) or (b), five rounds; (d) CbD: `Calibrator::compensate_pose` from the hint,
//! as `cbd compensate` does it (`evaluation::compensation::compensate_all_poses`).

use super::commanded::{commanded_accuracy, CommandedAccuracy, CommandedRow, Commander, Fitted, FittedCommand, SimulatedArm};
use super::correction::Predictor;
use crate::error::Error;
use crate::nominal::tool_points::{rotation_angle, tool_frame};
use crate::nominal::Frame;
use crate::report::stats::ErrorStats;
use cbd_protocol::NominalModel;
use cbd_runtime::internals::compensate_pose::{nominal_pose_inverse, MIN_POSE_JOINTS};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Gauss–Newton steps of the nominal pose inverse where there is no closed form.
const NOMINAL_POSE_ITERATIONS: usize = 16;
/// Pose-redefinition rounds of kernel-ridge compensation (as for position targets).
const POSE_REDEFINITION_ROUNDS: usize = 5;
/// Largest random change of each joint from q* to the hint (radians, as for position targets).
const HINT_PERTURBATION: f64 = 0.05;

/// Whether `nominal`'s targets are poses: at least six joints and tool points off a line.
pub fn takes_pose_targets(nominal: &NominalModel) -> bool {
    nominal.n_joints() >= MIN_POSE_JOINTS
        && nominal.tool_point_count() >= 3
        && cbd_runtime::internals::kinematics::tool_frame::determines_orientation(nominal.tool_points())
}

/// The table for `nominal`'s targets: poses ([`commanded_pose_accuracy`]) when it
/// [`takes_pose_targets`], positions otherwise (tool point 1's with several tool points).
pub fn commander_for(nominal: &NominalModel) -> Commander {
    if takes_pose_targets(nominal) {
        commanded_pose_accuracy
    } else {
        commanded_accuracy
    }
}

/// One method's commands: true origin errors, orientation errors (degrees), misses of its own model.
#[derive(Default)]
struct Tally {
    position: Vec<f64>,
    angle: Vec<f64>,
    not_reached: usize,
    forward_position: Vec<f64>,
    forward_angle: Vec<f64>,
    residual: Vec<f64>,
}

/// The table for `count` pose targets drawn from `seed` (module doc).
pub fn commanded_pose_accuracy(arm: &SimulatedArm, fitted: &Fitted<'_>, count: usize, seed: u64) -> crate::Result<CommandedAccuracy> {
    let n = arm.n_joints();
    let nominal = fitted.nominal;
    if nominal.n_joints() != n || !takes_pose_targets(nominal) {
        return Err(Error::InvalidInput(format!(
            "pose targets need a model of at least {MIN_POSE_JOINTS} joints (the simulated arm's {n}) with 3 tool points off a line"
        )));
    }
    let points: Vec<[f64; 3]> = nominal.tool_points().to_vec();
    let configurations = arm.random_configurations(count, seed);
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0xc0ffee);
    let truth =
        |q: &[f64]| arm.true_frame(q).ok_or_else(|| Error::InvalidInput("pose targets need the six-joint arm (--commanded six)".into()));
    let targets: Vec<Frame> = configurations.chunks_exact(n).map(truth).collect::<crate::Result<_>>()?;
    let hints: Vec<Vec<f64>> = configurations
        .chunks_exact(n)
        .map(|q| q.iter().map(|v| v + rng.gen_range(-HINT_PERTURBATION..HINT_PERTURBATION)).collect())
        .collect();
    let scale =
        (targets.iter().map(|t| t.translation().iter().map(|v| v * v).sum::<f64>()).sum::<f64>() / count.max(1) as f64).sqrt().max(1e-12);
    let lever = cbd_runtime::internals::compensate_pose::tool_lever(nominal);
    // Reached by the model's own account: the runtime's tolerances (1e-9 of the scale, its angle at the lever).
    let tolerance = 1e-9 * scale;
    let ik = |model: &NominalModel, target: &Frame, seed: &[f64]| -> (Vec<f64>, bool) {
        let mut q = vec![0.0; n];
        match nominal_pose_inverse(model, &target.translation(), &target.rotation(), seed, &mut q, NOMINAL_POSE_ITERATIONS, scale) {
            Ok((position, angle)) => (q, position <= tolerance && angle * lever <= tolerance),
            Err(_) => (seed.to_vec(), false),
        }
    };
    let mut names: Vec<String> = ["nominal", "dh"].map(String::from).to_vec();
    names.extend(fitted.peers.iter().map(|p| p.name.clone()));
    let mut tallies: Vec<Tally> = names.iter().map(|_| Tally::default()).collect();
    let record = |tally: &mut Tally, target: &Frame, q: &[f64], reached: bool| -> crate::Result<()> {
        let at = truth(q)?;
        tally.position.push(crate::nominal::norm(crate::nominal::sub(at.translation(), target.translation())));
        tally.angle.push(rotation_angle(&at, target).to_degrees());
        tally.not_reached += usize::from(!reached);
        Ok(())
    };
    let mut nominal_commands = Vec::with_capacity(count);
    for (target, hint) in targets.iter().zip(&hints) {
        // (a) nominal, (b) DH from (a)'s command.
        let (q_nominal, ok) = ik(nominal, target, hint);
        record(&mut tallies[0], target, &q_nominal, ok)?;
        if let Some(dh) = fitted.dh {
            let (q, ok) = ik(dh, target, &q_nominal);
            record(&mut tallies[1], target, &q, ok)?;
        }
        // (c) corrections by pose redefinition on the nominal model or on a calibrated chain.
        for (i, p) in fitted.peers.iter().enumerate() {
            if let FittedCommand::Redefine { chain, predict } = &p.command {
                let model = chain.as_deref().unwrap_or(nominal);
                let (q, ok) = pose_redefinition(model, predict, &points, target, &q_nominal, &ik);
                record(&mut tallies[2 + i], target, &q, ok)?;
            }
        }
        nominal_commands.push(q_nominal);
    }
    // (d) blobs (CbD): pose compensation from the hint, as `cbd compensate` commands target poses.
    for (i, p) in fitted.peers.iter().enumerate() {
        let FittedCommand::Compensate { blob } = &p.command else { continue };
        let (name, tally) = (&p.name, &mut tallies[2 + i]);
        let rows = crate::evaluation::compensation::compensate_all_poses(blob, &targets, Some(&hints))
            .map_err(|e| Error::InvalidInput(format!("{name}: pose compensation: {e}")))?;
        let model = cbd_protocol::decode(blob).map_err(|e| Error::from(e).context(name.as_str()))?;
        let mut storage = vec![0.0; cbd_runtime::storage_len_for(&model)];
        let mut cal = cbd_runtime::Calibrator::from_model(model, &mut storage).map_err(|e| Error::from(e).context(name.to_string()))?;
        for ((row, target), q_star) in rows.iter().zip(&targets).zip(configurations.chunks_exact(n)) {
            record(tally, target, &row.joints, row.compensation.reached)?;
            tally.residual.push(row.compensation.position_residual);
            let pose = cal.evaluate_pose(q_star).map_err(|e| Error::from(e).context(format!("{name}: evaluate_pose")))?;
            let forward = Frame::new(pose.rotation(), pose.origin());
            tally.forward_position.push(crate::nominal::norm(crate::nominal::sub(forward.translation(), target.translation())));
            tally.forward_angle.push(rotation_angle(&forward, target).to_degrees());
        }
    }
    let stats = |v: &[f64]| (!v.is_empty()).then(|| ErrorStats::of_errors(v));
    let rows = names
        .iter()
        .zip(&tallies)
        .filter(|(_, t)| !t.position.is_empty())
        .map(|(name, t)| CommandedRow {
            name: name.clone(),
            stats: ErrorStats::of_errors(&t.position),
            forward: stats(&t.forward_position),
            not_reached: t.not_reached,
            residual: stats(&t.residual),
            orientation_deg: stats(&t.angle),
            forward_orientation_deg: stats(&t.forward_angle),
        })
        .collect();
    Ok(CommandedAccuracy { targets: count, rows, target: "tool pose (the tool frame's origin and orientation)".into() })
}

/// A pose inverse kinematics: model, target frame, seed → (command, reached by the model's account).
type PoseIk<'a> = dyn Fn(&NominalModel, &Frame, &[f64]) -> (Vec<f64>, bool) + 'a;

/// Kernel-ridge compensation of a pose target by pose redefinition on the tool points: the
/// shifted points y'_j (first y*_j) → their frame → `ik` on `model` → y'_j += y*_j − krr_j(q).
fn pose_redefinition(
    model: &NominalModel,
    krr: &Predictor,
    points: &[[f64; 3]],
    target: &Frame,
    start: &[f64],
    ik: &PoseIk<'_>,
) -> (Vec<f64>, bool) {
    let wanted: Vec<[f64; 3]> = points.iter().map(|p| target.apply(*p)).collect();
    let mut shifted = wanted.clone();
    let (mut q, mut ok) = (start.to_vec(), false);
    for _ in 0..POSE_REDEFINITION_ROUNDS {
        let Some(frame) = tool_frame(points, &shifted) else { return (q, false) };
        (q, ok) = ik(model, &frame, &q);
        // Row r of the prediction is tool point r mod m_p: the configuration once per point.
        let rows: Vec<f64> = points.iter().flat_map(|_| q.iter().copied()).collect();
        let predicted = krr(&rows);
        for (j, (s, y)) in shifted.iter_mut().zip(&wanted).enumerate() {
            for c in 0..3 {
                s[c] += y[c] - predicted[3 * j + c];
            }
        }
    }
    (q, ok)
}

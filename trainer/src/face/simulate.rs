//! Measurements of a simulated "real" robot (`cbd simulate`, the Python package's `simulate`): the
//! rows as numbers, with the CSV's header; the front writes them or hands them back as arrays.

use crate::error::{Error, Result};
use crate::limits::MAX_MAGNITUDE;
use crate::simulate::{add_noise, configurations, rr, Sampling};

/// What to simulate: the flags of `cbd simulate` but its files (`--out`, `--poses`), and the
/// keywords of the Python package's `simulate` (one set of defaults).
#[derive(Debug, Clone, clap::Args, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SimulateSettings {
    /// Which robot: `rr` (the paper's planar arm; columns q1,q2 in rad, x,y) or `six` (a UR5-like
    /// arm with geometric errors and gravity joint compliance, noise 0.01 mm by default; columns
    /// as in examples/ur5/ur5.toml: q1_deg…q6_deg, x_mm, y_mm, z_mm; `--sampling uniform` or `walk`).
    #[arg(long, default_value_t = defaults::robot())]
    #[serde(default = "defaults::robot")]
    pub robot: String,
    /// `grid` (per-axis points given by --grid; rr only), `uniform` (--count random configurations)
    /// or `walk` (--count configurations along a random walk in joint space, in the order measured:
    /// Gaussian steps of --step radians per joint, reflected at the joint range's ends).
    #[arg(long, default_value_t = defaults::sampling())]
    #[serde(default = "defaults::sampling")]
    pub sampling: String,
    /// With `--sampling walk`: the standard deviation of each joint's step between consecutive
    /// rows, radians (a real arm's campaign: UR5 poses are 1–16° apart, about 0.05–0.15).
    #[arg(long)]
    pub step: Option<f64>,
    #[arg(long, default_value_t = defaults::grid())]
    #[serde(default = "defaults::grid")]
    pub grid: usize,
    #[arg(long, default_value_t = defaults::count())]
    #[serde(default = "defaults::count")]
    pub count: usize,
    #[arg(long, default_value_t = defaults::seed())]
    #[serde(default = "defaults::seed")]
    pub seed: u64,
    /// Standard deviation of Gaussian noise added to the measured positions
    /// (default: 0 for rr, the robot's own 0.01 mm for six).
    #[arg(long)]
    pub noise: Option<f64>,
    /// Inject an effect nobody declares (repeatable): [`effect_help`].
    #[arg(long = "effect", help = effect_help())]
    #[serde(default, rename = "effect", deserialize_with = "one_or_many")]
    pub effects: Vec<String>,
    /// Six-joint robot: measure several points on the tool, offsets in the tool frame (mm),
    /// `x,y,z;x,y,z;…` (at most 4; e.g. `0,0,0;100,0,0;50,86.60254037844386,0`: three points 100 mm
    /// apart). Columns x1_mm, y1_mm, z1_mm, x2_mm, …; the noise is per coordinate of every point.
    #[arg(long = "tool-points")]
    pub tool_points: Option<String>,
    /// With --tool-points (at least 3): also write each pose as measured by a 6-D probe — the
    /// least-squares tool frame of the noisy points, x_mm, y_mm, z_mm and qw, qx, qy, qz — and the
    /// point columns as that frame's points (so both sets of columns hold the same data).
    #[arg(long)]
    #[serde(default)]
    pub pose: bool,
    /// Six-joint robot: report the measurements in a tracker's frame instead of the robot's base
    /// frame, `tx,ty,tz;ax,ay,az,angle`: a point y of the base frame reads R y + t, R the turn by
    /// `angle` degrees about the axis (ax, ay, az) (any length but zero), t in mm. For a model file with
    /// `[chain] base = { register = true }` (README "Tracker frames").
    #[arg(long = "tracker-frame")]
    pub tracker_frame: Option<String>,
    /// The real arm's geometry is exactly the nominal one (rr: l1 = 1, l2 = 0.5, no base offset;
    /// six: the UR5 DH table, base and tool): only its effects — built-in or `--effect` — and the
    /// noise set it apart. For testing what a calibration does when there is no geometric error.
    #[arg(long)]
    #[serde(default)]
    pub exact_geometry: bool,
}

/// The flags' defaults, one source for the command line (clap) and the Python package's keyword
/// arguments (serde): `cli::settings_tests` checks that both read the same arguments from nothing.
mod defaults {
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

/// A list flag given as one value or as a list (`effect="…"` or `effect=["…", "…"]`).
fn one_or_many<'de, D: serde::Deserializer<'de>>(deserializer: D) -> std::result::Result<Vec<String>, D::Error> {
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

/// `--tracker-frame`: `tx,ty,tz;ax,ay,az,angle_deg` → the motion y ↦ R y + t.
fn parse_tracker_frame(text: &str) -> Result<crate::nominal::Frame> {
    let bad = |why: &str| {
        Error::InvalidInput(format!(
            "--tracker-frame `{text}`: {why} (expected tx,ty,tz;ax,ay,az,angle: a translation in mm, an axis and an angle in degrees)"
        ))
    };
    let groups: Vec<Vec<f64>> = text
        .split(';')
        .map(|g| g.split(',').map(|x| x.trim().parse::<f64>()).collect::<std::result::Result<Vec<f64>, _>>())
        .collect::<std::result::Result<_, _>>()
        .map_err(|e| bad(&e.to_string()))?;
    let [t, r] = groups.as_slice() else { return Err(bad("two groups separated by `;`")) };
    if t.len() != 3 || r.len() != 4 {
        return Err(bad("3 numbers, then 4"));
    }
    if let Some(v) = t.iter().chain(r).find(|v| !v.is_finite()) {
        return Err(bad(&format!("{v} is not a finite number")));
    }
    if let Some(v) = t.iter().chain(r).find(|v| v.abs() > MAX_MAGNITUDE) {
        return Err(bad(&format!("{} is beyond ±{MAX_MAGNITUDE:e}", crate::error::as_written(*v))));
    }
    let length = (r[0] * r[0] + r[1] * r[1] + r[2] * r[2]).sqrt();
    if !(length > 0.0 && length.is_finite()) {
        return Err(bad("the axis must not be zero"));
    }
    let axis = [r[0] / length, r[1] / length, r[2] / length];
    Ok(crate::nominal::rotation_about(axis, r[3].to_radians()).with_translation([t[0], t[1], t[2]]))
}

/// Every measured position (3 coordinates per row) seen from `frame` (`--tracker-frame`).
fn into_tracker_frame(positions: &mut [f64], frame: Option<&crate::nominal::Frame>) {
    if let Some(frame) = frame {
        for y in positions.chunks_exact_mut(3) {
            y.copy_from_slice(&frame.apply([y[0], y[1], y[2]]));
        }
    }
}

/// `--tool-points`: `x,y,z;x,y,z;…`, 1 to 4 distinct finite points.
fn parse_tool_points(text: &str) -> Result<Vec<[f64; 3]>> {
    let bad = |why: String| Error::InvalidInput(format!("--tool-points `{text}`: {why} (expected x,y,z;x,y,z;… in mm)"));
    let mut points = Vec::new();
    for (j, part) in text.split(';').enumerate() {
        let v: Vec<f64> = part
            .split(',')
            .map(|x| x.trim().parse::<f64>())
            .collect::<std::result::Result<_, _>>()
            .map_err(|e| bad(format!("point {}: {e}", j + 1)))?;
        let [x, y, z] = v[..] else { return Err(bad(format!("point {} has {} coordinates; it needs exactly 3", j + 1, v.len()))) };
        points.push([x, y, z]);
    }
    // The rules of a model file's `[chain.tool] points`: what is simulated can be read back.
    crate::nominal::tool_points::check_tool_points(&points).map_err(bad)?;
    Ok(points)
}

/// The joint columns `cbd simulate` writes for `robot`, read back as a file of poses (`--poses`:
/// errors name the file, line and column, as for measurements).
pub fn poses_spec(robot: &str) -> crate::data::csv_import::ColumnSpec {
    use crate::data::csv_import::{default_joint_limits, ColumnSpec};
    use crate::data::model_file::{AngleUnit, LengthUnit};
    let (joints, angle_unit, length_unit): (Vec<String>, _, _) = if robot == "six" {
        ((1..=6).map(|k| format!("q{k}_deg")).collect(), AngleUnit::Deg, LengthUnit::Mm)
    } else {
        (vec!["q1".into(), "q2".into()], AngleUnit::Rad, LengthUnit::M)
    };
    let kinds = vec![cbd_protocol::JointKind::Revolute; joints.len()];
    ColumnSpec {
        joint_columns: joints,
        position_columns: Vec::new(),
        joint_limits: default_joint_limits(&kinds),
        joint_kinds: kinds,
        angle_unit,
        length_unit,
        model_length_unit: length_unit,
        min_rows: 1,
        repeat_tolerance: None,
        joint_map: None,
        planar_frame: None,
        tool_points: Vec::new(),
        orientation_columns: None,
        order: crate::data::RowOrder::Measured,
        range_hint: "the simulated robot's joints are read within one turn each way",
    }
}

/// What `cbd simulate` writes: the CSV's header and its rows (row-major, one value per column,
/// each the number the CSV holds), and what they are ("300 measurements of the simulated six-joint
/// arm").
#[derive(Debug, Clone, PartialEq)]
pub struct Simulated {
    pub header: Vec<String>,
    pub values: Vec<f64>,
    pub what: String,
}

impl Simulated {
    fn new(header: Vec<String>, what: String) -> Simulated {
        Simulated { header, values: Vec::new(), what }
    }

    pub fn rows(&self) -> usize {
        self.values.len() / self.header.len().max(1)
    }
}

impl SimulateSettings {
    /// Refuses what the settings cannot simulate, before any work — in particular before a front
    /// reads `--poses` (`poses_given`), so that a wrong flag is named first.
    pub fn check(&self, poses_given: bool) -> Result<()> {
        self.checked(poses_given).map(|_| ())
    }

    /// [`Self::check`], keeping what it parsed: the walk's step ([`walk_step`], `None` unless
    /// walking), the six-joint arm's planted changes (issue 50: they come out of the effect list,
    /// the arm keeping its other errors and its built-in compliance) and the effects left.
    fn checked(&self, poses_given: bool) -> Result<Checked> {
        if let Some(noise) = self.noise {
            // The importers' bound: a CSV that `cbd` writes, `cbd` reads back.
            if !(noise >= 0.0 && noise <= MAX_MAGNITUDE) {
                return Err(Error::InvalidInput(format!(
                    "--noise must be a number in [0, {MAX_MAGNITUDE:e}] (the bound every imported value obeys), got {noise:e}"
                )));
            }
        }
        if self.sampling == "grid" && self.grid < 2 {
            return Err(Error::InvalidInput(format!("--grid must be at least 2 points per joint, got {}", self.grid)));
        }
        if (self.sampling == "uniform" || self.sampling == "walk") && self.count == 0 {
            return Err(Error::InvalidInput("--count must be at least 1".into()));
        }
        let step = walk_step(self)?;
        check_simulation_memory(self, crate::memory::available_bytes())?;
        let (mut planted, mut effects) = (Vec::new(), Vec::new());
        match self.robot.as_str() {
            "rr" if self.tool_points.is_some() || self.pose || self.tracker_frame.is_some() => {
                return Err(Error::InvalidInput(
                    "--tool-points, --pose and --tracker-frame are for the six-joint robot (--robot six)".into(),
                ))
            }
            "rr" => {
                effects = self.effects.clone();
                if !matches!(self.sampling.as_str(), "grid" | "uniform" | "walk") {
                    let other = &self.sampling;
                    return Err(Error::InvalidInput(format!("unknown sampling `{other}` (expected grid, uniform or walk)")));
                }
            }
            "six" => {
                for spec in &self.effects {
                    match crate::simulate::planted::parse_planted(spec, 6) {
                        Some(p) => planted.push(p?),
                        None => effects.push(spec.clone()),
                    }
                }
                if !matches!(self.sampling.as_str(), "uniform" | "walk") && !poses_given {
                    return Err(Error::InvalidInput("the six-joint robot is sampled with --sampling uniform or walk".into()));
                }
                self.tracker_frame.as_deref().map(parse_tracker_frame).transpose()?;
            }
            other => return Err(Error::InvalidInput(format!("unknown robot `{other}` (expected rr or six)"))),
        }
        Ok(Checked { step, planted, effects })
    }
}

/// What [`SimulateSettings::checked`] parsed.
struct Checked {
    step: Option<f64>,
    planted: Vec<crate::simulate::planted::Planted>,
    /// The `--effect` specs but the planted changes.
    effects: Vec<String>,
}

/// The rows `cbd simulate` writes, as numbers; `poses` (radians, row-major, read with
/// [`poses_spec`]) are measured instead of sampling. One function for the command and the Python package.
pub fn simulate(settings: &SimulateSettings, poses: Option<Vec<f64>>) -> Result<Simulated> {
    let Checked { step, planted, effects } = settings.checked(poses.is_some())?;
    let args = &SimulateSettings { effects, ..settings.clone() };
    if args.robot == "six" {
        return simulate_six(args, step, &planted, poses);
    }
    let sampling = match args.sampling.as_str() {
        "grid" => Sampling::Grid { per_axis: args.grid },
        "uniform" => Sampling::Uniform { count: args.count, seed: args.seed },
        _ => Sampling::Walk { count: args.count, step: step.unwrap_or(0.0), seed: args.seed },
    };
    let joints = match poses {
        Some(poses) => poses,
        None => configurations(sampling, 2),
    };
    let real = if args.exact_geometry {
        rr::RealRr { lengths: cbd_protocol::paper_rr::LENGTHS, base_offset: [0.0; 2], ..rr::RealRr::default() }
    } else {
        rr::RealRr::default()
    };
    let mut data = if args.effects.is_empty() {
        real.measure(&joints)
    } else {
        let lengths = real.lengths;
        let rigid = cbd_protocol::NominalModel::planar(&lengths).ok_or_else(|| Error::Internal("two links fit".into()))?;
        // Noise comes below; the seed draws any drift.
        effect_arm(rigid, &args.effects)?.measure(&joints, 0.0, args.seed)
    };
    add_noise(&mut data.positions, args.noise.unwrap_or(0.0), args.seed.wrapping_add(0x5eed));
    check_readable(&data)?;
    let mut table = Simulated::new(["q1", "q2", "x", "y"].map(String::from).into(), format!("{} measurements", data.len()));
    for i in 0..data.len() {
        let (q, y) = (data.joints(i), data.position(i));
        table.values.extend([q[0], q[1], y[0], y[1]]);
    }
    Ok(table)
}

/// The six-joint robot's rows; `step`: the walk's ([`walk_step`]), `None` unless walking.
fn simulate_six(
    args: &SimulateSettings,
    step: Option<f64>,
    planted: &[crate::simulate::planted::Planted],
    poses: Option<Vec<f64>>,
) -> Result<Simulated> {
    use crate::simulate::six_joint::{random_configurations, SixJointRobot};
    let mut robot = SixJointRobot::ur5_like(1);
    if args.exact_geometry {
        robot.real = crate::simulate::six_joint::ur5_nominal();
    }
    for change in planted {
        change.apply(&mut robot.real);
    }
    if let Some(noise) = args.noise {
        robot.noise_std = noise;
    }
    let tracker = args.tracker_frame.as_deref().map(parse_tracker_frame).transpose()?;
    let joints = match (poses, step) {
        (Some(poses), _) => poses,
        (None, Some(step)) => crate::simulate::six_joint::walk_configurations(args.count, step, args.seed),
        (None, None) => random_configurations(args.count, args.seed),
    };
    if let Some(points) = &args.tool_points {
        return simulate_six_points(args, &robot, &joints, &parse_tool_points(points)?, tracker.as_ref());
    }
    if args.pose {
        return Err(Error::InvalidInput("--pose needs --tool-points (at least 3 points)".into()));
    }
    let mut data = if args.effects.is_empty() {
        robot.measure(&joints, args.seed.wrapping_add(0x5eed))
    } else {
        let rigid = cbd_protocol::NominalModel::DhChain(robot.real.clone());
        effect_arm(rigid, &args.effects)?.measure(&joints, robot.noise_std, args.seed.wrapping_add(0x5eed))
    };
    into_tracker_frame(&mut data.positions, tracker.as_ref());
    check_readable(&data)?;
    let header = ["q1_deg", "q2_deg", "q3_deg", "q4_deg", "q5_deg", "q6_deg", "x_mm", "y_mm", "z_mm"].map(String::from).into();
    let mut table = Simulated::new(header, format!("{} measurements of the simulated six-joint arm", data.len()));
    for i in 0..data.len() {
        table.values.extend(data.joints(i).iter().map(|v| v.to_degrees()));
        table.values.extend_from_slice(data.position(i));
    }
    Ok(table)
}

/// The six-joint arm measured at several tool points: each point's noise-free position (the real
/// chain with its tool moved to the point, `nominal::tool_points::point_chain`), then noise on every
/// coordinate, all seen from `tracker` if given; with `--pose`, the least-squares tool frame of each
/// pose's noisy points as well.
fn simulate_six_points(
    args: &SimulateSettings,
    robot: &crate::simulate::six_joint::SixJointRobot,
    joints: &[f64],
    tool_points: &[[f64; 3]],
    tracker: Option<&crate::nominal::Frame>,
) -> Result<Simulated> {
    use crate::nominal::tool_points::{point_chain, point_of_pose, quaternion_of, rotation_of_quaternion, tool_frame};
    let p = tool_points.len();
    if args.pose && !cbd_runtime::internals::kinematics::tool_frame::determines_orientation(tool_points) {
        return Err(Error::InvalidInput(format!(
            "--pose needs at least 3 tool points off one line (--tool-points has {p}{}): the tool frame's orientation is not determined",
            if p >= 3 { " on a line" } else { "" }
        )));
    }
    let mut per_point = Vec::with_capacity(p);
    for point in tool_points {
        let mut moved = robot.clone();
        moved.real = point_chain(&robot.real, *point);
        let truth: Vec<f64> = if args.effects.is_empty() {
            joints.chunks_exact(6).flat_map(|q| moved.true_position(q)).collect()
        } else {
            let rigid = cbd_protocol::NominalModel::DhChain(moved.real.clone());
            // Noise comes below; the seed draws any drift, the same at every point of a pose.
            effect_arm(rigid, &args.effects)?.measure(joints, 0.0, args.seed).positions
        };
        per_point.push(truth);
    }
    let poses = joints.len() / 6;
    // Pose-major: pose k's points in turn, then noise on every coordinate.
    let mut values: Vec<f64> = (0..poses).flat_map(|k| per_point.iter().flat_map(move |t| t[3 * k..3 * k + 3].to_vec())).collect();
    add_noise(&mut values, robot.noise_std, args.seed.wrapping_add(0x5eed));
    into_tracker_frame(&mut values, tracker);
    let mut data = crate::data::Measurements::with_points(6, 3, p);
    for (k, q) in joints.chunks_exact(6).enumerate() {
        for j in 0..p {
            data.push(q, &values[3 * (k * p + j)..3 * (k * p + j) + 3]);
        }
    }
    check_readable(&data)?;
    let mut header: Vec<String> = (1..=6).map(|k| format!("q{k}_deg")).collect();
    header.extend((1..=p).flat_map(|j| ["x", "y", "z"].map(|c| format!("{c}{j}_mm"))));
    if args.pose {
        header.extend(["x_mm", "y_mm", "z_mm", "qw", "qx", "qy", "qz"].map(String::from));
    }
    let mut table = Simulated::new(header, format!("{poses} poses ({p} tool points each) of the simulated six-joint arm"));
    for k in 0..poses {
        let fields = &mut table.values;
        fields.extend(data.joints(k * p).iter().map(|v| v.to_degrees()));
        let measured: Vec<[f64; 3]> = (0..p).map(|j| std::array::from_fn(|c| data.position(k * p + j)[c])).collect();
        if args.pose {
            let frame = tool_frame(tool_points, &measured)
                .ok_or_else(|| Error::InvalidInput("--tool-points on a line: no tool frame for --pose".into()))?;
            // The point columns are the points of the pose as written (its quaternion's rotation):
            // both column sets hold the same data, to the last bit.
            let (origin, quaternion) = (frame.translation(), quaternion_of(&frame.rotation()));
            let norm = quaternion.iter().map(|v| v * v).sum::<f64>().sqrt();
            let rotation = rotation_of_quaternion(quaternion.map(|v| v / norm));
            for pj in tool_points {
                fields.extend(point_of_pose(&origin, &rotation, pj));
            }
            fields.extend(origin);
            fields.extend(quaternion);
        } else {
            fields.extend(measured.iter().flatten());
        }
    }
    Ok(table)
}

/// `--step` with `--sampling walk` (required there, a positive finite number of radians up to π);
/// refused with any other sampling, where it would be ignored. `None` unless walking.
fn walk_step(args: &SimulateSettings) -> Result<Option<f64>> {
    match (args.sampling.as_str(), args.step) {
        ("walk", None) => Err(Error::InvalidInput("--sampling walk needs --step (radians per joint between consecutive rows)".into())),
        ("walk", Some(step)) if !(step > 0.0 && step <= std::f64::consts::PI) => {
            Err(Error::InvalidInput(format!("--step must be a number of radians in (0, π], got {step:e}")))
        }
        ("walk", Some(step)) => Ok(Some(step)),
        (other, Some(_)) => Err(Error::InvalidInput(format!("--step is for --sampling walk, not `{other}`"))),
        (_, None) => Ok(None),
    }
}

/// Refuses to write positions the importers would refuse to read back (beyond ±1e100: noise and
/// effects that are each in range can still add up, a thermal drift over many rows), naming the row.
fn check_readable(data: &crate::data::Measurements) -> Result<()> {
    let m = data.task_dim.max(1);
    match data.positions.iter().position(|v| !(v.abs() <= MAX_MAGNITUDE)) {
        Some(k) => Err(Error::InvalidInput(format!(
            "the simulated position of row {} reaches {:.3e}, beyond the ±{MAX_MAGNITUDE:e} `cbd` reads back: lower --noise or the --effect sizes",
            k / m + 1,
            data.positions[k]
        ))),
        None => Ok(()),
    }
}

/// The rigid "real" geometry plus the `--effect` specs (undeclared: only the CSV carries them).
fn effect_arm(rigid: cbd_protocol::NominalModel, specs: &[String]) -> Result<crate::simulate::effects::EffectArm> {
    let n = rigid.n_joints();
    let mut arm = crate::simulate::effects::EffectArm::new(rigid);
    for spec in specs {
        arm = arm.with(crate::simulate::effects::parse_effect(spec, n)?);
    }
    Ok(arm)
}

/// Refuses a simulation whose rows cannot be held in `available` bytes (a `--grid 100000` of the
/// RR arm is 10¹⁰ rows), naming the rows, the figure and the flag that sets them.
fn check_simulation_memory(args: &SimulateSettings, available: Option<f64>) -> Result<()> {
    if args.robot == "six" && !matches!(args.sampling.as_str(), "uniform" | "walk") {
        return Ok(()); // refused below: the six-joint arm is sampled uniformly or by a walk only
    }
    let (joints, coordinates) = if args.robot == "six" { (6, 3) } else { (2, 2) };
    let (rows, flag) = if args.sampling == "grid" {
        ((args.grid as f64).powi(joints as i32), format!("--grid {}", args.grid))
    } else {
        (args.count as f64, format!("--count {}", args.count))
    };
    let need = crate::memory::simulate_bytes(rows, joints + coordinates);
    match available {
        Some(available) if need > available => Err(crate::memory::MemoryError(format!(
            "{flag} makes {rows:e} rows, about {} to simulate and write, more than the {} this process may use; lower {}",
            crate::memory::gigabytes(need),
            crate::memory::gigabytes(available),
            flag.split(' ').next().unwrap_or("it")
        ))
        .into()),
        _ => Ok(()),
    }
}

/// `--effect`'s help: the library's types from `effects::KINDS` (those with a model-file entry,
/// keys in its order), then the simulator's own.
fn effect_help() -> String {
    let library: Vec<String> = crate::effects::KINDS
        .iter()
        .filter(|k| !k.file_fields().is_empty())
        .map(|k| format!("{}:{}", k.name(), k.file_fields().iter().map(|(key, _)| format!("{key}=")).collect::<Vec<_>>().join(",")))
        .collect();
    format!(
        "Inject an effect nobody declares (repeatable): `type:key=value,...` with joints/links 1-based, angles in radians, \
         lengths in the model's unit (rr: 1 = l1; six: mm), compliance in rad per (mass·length) under unit link masses and \
         unit gravity (−y for rr, −z for six). Library types: {}. Outside the library: bump:centre=q1;q2;...,width=,dx=,dy=,dz= \
         | dead_zone:joint=,width= | thermal:dx=,dy=,dz= (drift per row) | drift:sd=,length= (a stationary random \
         process over the rows, each coordinate an AR(1)/Ornstein–Uhlenbeck sequence: standard deviation sd in the model's \
         unit, correlation exp(−|i − j|/length) between rows i and j; drawn from --seed). With any --effect the robot is its geometry (rr: \
         link lengths 1.09, 0.46; six: its DH, base and tool errors) plus these effects only: the built-in \
         bending/stretch/base offset (rr) and joint compliance (six) are left out. Planted changes of the six-joint arm's \
         geometry (`cbd check`: a calibration set and a changed set from the same arm; the arm keeps its compliance): \
         joint_zero:joint=,offset= (radians) | base_shift:dx=,dy=,dz= | tool_shift:dx=,dy=,dz= (flange frame) | \
         link_length:link=,delta= (DH a) | length_scale:scale= (every length of the chain)",
        library.join(" | ")
    )
}

//! Physical effects injected into simulated measurements, implemented here independently of the
//! runtime's `cbd_runtime::internals::kinematics::augmented` (gravity torques by differentiating the potential
//! energy numerically, effects composed here; only the rigid DH frames come from the runtime's one
//! walk, `dh_walk`, itself checked against a URDF chain walk in `nominal::urdf`): an independent check of what `cbd diagnose` finds and of what
//! the runtime evaluates. Also effects outside the diagnosis library (a localized bump, a dead
//! zone, a thermal-like drift) for testing that they are reported as unexplained structure.
//!
//! Augmented kinematics (as `cbd_protocol::effects` defines it): k(q) = k_rigid(q + δ(q)) + b(q) (+ the outside terms).

pub use crate::effects::EffectSpecError;
use crate::effects::{Injected, Instance, Kind, SimulatedArm, Spec, KINDS};
use crate::nominal::{dot, Frame};
use cbd_protocol::{Effect, GravityModel, NominalModel};
use cbd_runtime::internals::kinematics::forward_kinematics;
use cbd_runtime::internals::kinematics::rigid::dh_walk;

/// One injected effect: a kind of the library (`effects::KINDS`, its blob form converts with
/// `From<Effect>`), or one outside it. `joint` is 0-based.
#[derive(Debug, Clone, PartialEq)]
pub enum InjectedEffect {
    /// An effect of the library, injected by its descriptor (`effects::EffectKind::inject`).
    Library(Instance),
    /// Outside the library: task-space displacement `amplitude` · exp(−|q − centre|² / (2 width²))
    /// (joint-space distance, angles wrapped to (−π, π]).
    Bump { centre: Vec<f64>, width: f64, amplitude: [f64; 3] },
    /// Outside the library: joint `joint` does not move within ±`width` of zero
    /// (q_eff = sign(q) max(|q| − width, 0)), a hysteresis-free dead zone.
    DeadZone { joint: usize, width: f64 },
    /// Outside the library: every task coordinate drifts by `per_row` × row index (a warming
    /// machine measured in sequence; not a function of the configuration at all).
    ThermalDrift { per_row: [f64; 3] },
    /// Outside the library: a stationary random process over the row sequence added to every
    /// measured coordinate independently (`super::row_drift`: standard deviation `sd` in the
    /// model's length unit, correlation exp(−|i − j| / `length`) between rows i and j). A nuisance
    /// of the measurement (settling, warming, a tracker's own drift), not of the configuration:
    /// [`EffectArm::measure`] adds it, [`EffectArm::position`] (one row, no sequence) does not.
    Drift { sd: f64, length: f64 },
}

impl From<Effect> for InjectedEffect {
    fn from(e: Effect) -> InjectedEffect {
        InjectedEffect::Library(Instance::of(&e))
    }
}

impl From<Instance> for InjectedEffect {
    fn from(e: Instance) -> InjectedEffect {
        InjectedEffect::Library(e)
    }
}

impl InjectedEffect {
    /// Whether `cbd diagnose`'s library can represent it.
    pub fn in_library(&self) -> bool {
        matches!(self, InjectedEffect::Library(_))
    }
}

/// A simulated arm: a rigid chain (the "real" geometry; its own effect list is ignored) plus
/// undeclared effects, under the gravity/mass model `gravity`.
#[derive(Debug, Clone, PartialEq)]
pub struct EffectArm {
    pub rigid: NominalModel,
    pub gravity: GravityModel,
    /// r_k: centre of mass of link k in its own frame (the frame at its distal end); empty: every
    /// centre at its link's end (the point-mass model).
    pub centres_of_mass: Vec<[f64; 3]>,
    pub effects: Vec<InjectedEffect>,
}

/// Distal ends c_k of every link (k = 0..n) and the start of link 0, on the rigid chain at `q`.
/// DH: origins of frames 1..n (frame 0 = base); planar: ends of the links from the origin.
fn link_points(rigid: &NominalModel, q: &[f64]) -> Vec<[f64; 3]> {
    match rigid {
        NominalModel::DhChain(chain) => {
            let walk = dh_walk(chain, q);
            std::iter::once(walk.start).chain(walk.ends.into_iter().take(chain.joints.len())).collect()
        }
        NominalModel::PlanarChain { lengths, .. } => {
            let mut out = vec![[0.0; 3]];
            let (mut p, mut theta) = ([0.0; 3], 0.0);
            for (l, qk) in lengths.iter().zip(q) {
                theta += qk;
                p[0] += l * theta.cos();
                p[1] += l * theta.sin();
                out.push(p);
            }
            out
        }
    }
}

/// The frame of every link k = 0..n at its distal end: DH frames 1..n; planar: the link's end,
/// rotated by q_1 + … + q_k about z (x along the link).
fn link_frames(rigid: &NominalModel, q: &[f64]) -> Vec<Frame> {
    match rigid {
        NominalModel::DhChain(chain) => {
            let walk = dh_walk(chain, q);
            walk.end_rotations.into_iter().zip(walk.ends).take(chain.joints.len()).map(|(r, t)| Frame::new(r, t)).collect()
        }
        NominalModel::PlanarChain { lengths, .. } => {
            let (mut p, mut theta) = ([0.0; 3], 0.0);
            lengths
                .iter()
                .zip(q)
                .map(|(l, qk)| {
                    theta += qk;
                    p[0] += l * theta.cos();
                    p[1] += l * theta.sin();
                    let (s, c) = theta.sin_cos();
                    Frame::new([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]], p)
                })
                .collect()
        }
    }
}

fn gravity_vector(rigid: &NominalModel, gravity: &GravityModel) -> [f64; 3] {
    match rigid {
        NominalModel::PlanarChain { .. } => [gravity.direction[0], gravity.direction[1], 0.0],
        NominalModel::DhChain(_) => gravity.direction,
    }
}

fn mass(gravity: &GravityModel, k: usize) -> f64 {
    gravity.link_masses.get(k).copied().unwrap_or(1.0)
}

/// V(q) = Σ_k m_k g·c_k(q): minus the potential energy of the point masses (so that τ = ∂V/∂q).
fn gravity_potential(rigid: &NominalModel, gravity: &GravityModel, q: &[f64]) -> f64 {
    let g = gravity_vector(rigid, gravity);
    link_points(rigid, q).iter().skip(1).enumerate().map(|(k, c)| mass(gravity, k) * dot(g, *c)).sum()
}

/// V(q) = Σ_k g·(m_k o_k(q) + R_k(q) s_k) for the moments `moment(k) = (m_k, s_k)`.
fn moment_potential(rigid: &NominalModel, gravity: &GravityModel, q: &[f64], moment: &dyn Fn(usize) -> (f64, [f64; 3])) -> f64 {
    let g = gravity_vector(rigid, gravity);
    link_frames(rigid, q)
        .iter()
        .enumerate()
        .map(|(k, frame)| {
            let (m, s) = moment(k);
            m * dot(g, frame.translation()) + dot(g, frame.rotate(s))
        })
        .sum()
}

/// ∂f/∂q_j by central differences (step 1e-6; f is smooth, error ~1e-12 relative).
fn gradient(q: &[f64], f: impl Fn(&[f64]) -> f64) -> Vec<f64> {
    let h = 1e-6;
    (0..q.len())
        .map(|j| {
            let mut qp = q.to_vec();
            qp[j] += h;
            let vp = f(&qp);
            qp[j] -= 2.0 * h;
            let vm = f(&qp);
            (vp - vm) / (2.0 * h)
        })
        .collect()
}

/// τ_j(q) = ∂V/∂q_j of the point masses by central differences.
pub fn gravity_torques_numerical(rigid: &NominalModel, gravity: &GravityModel, q: &[f64]) -> Vec<f64> {
    gradient(q, |x| gravity_potential(rigid, gravity, x))
}

/// τ_j(q) = ∂V/∂q_j of masses m_k (`gravity.link_masses`, 1 by default) with centres r_k in their
/// link frames (s_k = m_k r_k), by central differences.
pub fn gravity_torques_of_distribution(rigid: &NominalModel, gravity: &GravityModel, centres: &[[f64; 3]], q: &[f64]) -> Vec<f64> {
    let moment = |k: usize| {
        let m = mass(gravity, k);
        let r = centres.get(k).copied().unwrap_or([0.0; 3]);
        (m, [m * r[0], m * r[1], m * r[2]])
    };
    gradient(q, |x| moment_potential(rigid, gravity, x, &moment))
}

fn wrap(a: f64) -> f64 {
    a.sin().atan2(a.cos())
}

impl EffectArm {
    /// A rigid chain with no effect yet, gravity from the chain's own effects' gravity model.
    pub fn new(rigid: NominalModel) -> EffectArm {
        let gravity = rigid.effects().gravity.clone();
        let mut rigid = rigid;
        rigid.effects_mut().list.clear();
        EffectArm { rigid, gravity, centres_of_mass: Vec::new(), effects: Vec::new() }
    }

    /// The same arm with link masses `masses` whose centres are `centres` (link frames).
    pub fn with_mass_distribution(mut self, masses: &[f64], centres: &[[f64; 3]]) -> EffectArm {
        self.gravity.link_masses = heapless::Vec::from_slice(masses).expect("at most MAX_JOINTS links");
        self.centres_of_mass = centres.to_vec();
        self
    }

    /// τ(q) of the arm's mass distribution (rigid chain at q).
    pub fn gravity_torques(&self, q: &[f64]) -> Vec<f64> {
        if self.centres_of_mass.is_empty() {
            gravity_torques_numerical(&self.rigid, &self.gravity, q)
        } else {
            gravity_torques_of_distribution(&self.rigid, &self.gravity, &self.centres_of_mass, q)
        }
    }

    pub fn with(mut self, effect: impl Into<InjectedEffect>) -> EffectArm {
        self.effects.push(effect.into());
        self
    }

    /// Joint deflection δ(q).
    pub fn deflection(&self, q: &[f64]) -> Vec<f64> {
        let mut delta = vec![0.0; q.len()];
        for e in &self.effects {
            match *e {
                InjectedEffect::Library(ref e) if !e.kind.task_space() => {
                    if let Injected::Joint(joint, v) = e.kind.inject(e, self, q) {
                        delta[joint] += v;
                    }
                }
                InjectedEffect::DeadZone { joint, width } => {
                    let v = q[joint];
                    delta[joint] += v.signum() * (v.abs() - width).max(0.0) - v;
                }
                _ => {}
            }
        }
        delta
    }

    /// Task-space terms that do not go through the joints: bending, bumps, drift at row `row`.
    fn task_terms(&self, q: &[f64], row: usize) -> [f64; 3] {
        let mut b = [0.0; 3];
        for e in &self.effects {
            match e {
                InjectedEffect::Library(e) if e.kind.task_space() => {
                    if let Injected::Task(v) = e.kind.inject(e, self, q) {
                        for c in 0..3 {
                            b[c] += v[c];
                        }
                    }
                }
                InjectedEffect::Bump { centre, width, amplitude } => {
                    let d2: f64 = q.iter().zip(centre).map(|(a, c)| wrap(a - c).powi(2)).sum();
                    let w = (-d2 / (2.0 * width * width)).exp();
                    for c in 0..3 {
                        b[c] += amplitude[c] * w;
                    }
                }
                InjectedEffect::ThermalDrift { per_row } => {
                    for c in 0..3 {
                        b[c] += per_row[c] * row as f64;
                    }
                }
                _ => {}
            }
        }
        b
    }

    /// Noise-free position at commanded joints `q`, measured as row `row` of a sequence.
    pub fn position(&self, q: &[f64], row: usize) -> Vec<f64> {
        let delta = self.deflection(q);
        let moved: Vec<f64> = q.iter().zip(&delta).map(|(a, d)| a + d).collect();
        let k = forward_kinematics(&self.rigid, &moved);
        let b = self.task_terms(q, row);
        (0..self.rigid.task_dim()).map(|c| k.position[c] + b[c]).collect()
    }

    /// Adds the drift effects to `positions` (row-major, `m` ≤ 3 coordinates a row: the first `m`
    /// of each row's three drift coordinates), drawn from `seed` (each drift its own stream).
    fn add_drift(&self, positions: &mut [f64], m: usize, seed: u64) {
        let rows = positions.len() / m.max(1);
        let drifts = self.effects.iter().filter_map(|e| match *e {
            InjectedEffect::Drift { sd, length } => Some((sd, length)),
            _ => None,
        });
        for (k, (sd, length)) in drifts.enumerate() {
            // A stream apart from the noise's (`add_noise` draws from `seed` itself).
            let stream = seed ^ 0xd21f_7000_0000_0000u64.wrapping_add(k as u64);
            let drift = super::row_drift(rows, 3, sd, length, stream);
            for (p, d) in positions.chunks_exact_mut(m.max(1)).zip(drift.chunks_exact(3)) {
                for (v, x) in p.iter_mut().zip(d) {
                    *v += x;
                }
            }
        }
    }

    /// Measurements at `joints` (row-major), with Gaussian noise of standard deviation `noise`
    /// drawn from `seed` (and any drift from a stream of the same seed).
    pub fn measure(&self, joints: &[f64], noise: f64, seed: u64) -> crate::data::Measurements {
        let n = self.rigid.n_joints();
        let mut positions: Vec<f64> = joints.chunks_exact(n).enumerate().flat_map(|(i, q)| self.position(q, i)).collect();
        self.add_drift(&mut positions, self.rigid.task_dim(), seed);
        super::add_noise(&mut positions, noise, seed);
        crate::data::Measurements {
            n_joints: n,
            task_dim: self.rigid.task_dim(),
            points_per_pose: 1,
            joints: joints.to_vec(),
            positions,
            order: crate::data::RowOrder::Measured,
        }
    }

    /// [`measure`](Self::measure) in the plane: the first two coordinates, for a planar arm whose
    /// rigid geometry is a DH form (base offset, joint offsets: `rr::planar_arm`).
    pub fn measure_planar(&self, joints: &[f64], noise: f64, seed: u64) -> crate::data::Measurements {
        let n = self.rigid.n_joints();
        let full = self.rigid.task_dim();
        let mut positions: Vec<f64> =
            joints.chunks_exact(n).enumerate().flat_map(|(i, q)| self.position(q, i).into_iter().take(2).collect::<Vec<_>>()).collect();
        self.add_drift(&mut positions, 2, seed);
        super::add_noise(&mut positions, noise, seed);
        debug_assert!(full >= 2);
        crate::data::Measurements {
            n_joints: n,
            task_dim: 2,
            points_per_pose: 1,
            joints: joints.to_vec(),
            positions,
            order: crate::data::RowOrder::Measured,
        }
    }
}

impl SimulatedArm for EffectArm {
    fn gravity_torques(&self, q: &[f64]) -> Vec<f64> {
        EffectArm::gravity_torques(self, q)
    }
    fn moment_torque(&self, q: &[f64], joint: usize, link: usize, mass: f64, first_moment: [f64; 3]) -> f64 {
        let one = |k: usize| if k == link { (mass, first_moment) } else { (0.0, [0.0; 3]) };
        gradient(q, |x| moment_potential(&self.rigid, &self.gravity, x, &one))[joint]
    }
    fn link_points(&self, q: &[f64]) -> Vec<[f64; 3]> {
        link_points(&self.rigid, q)
    }
    fn gravity(&self) -> [f64; 3] {
        gravity_vector(&self.rigid, &self.gravity)
    }
}

/// Parses `type:key=value,...`, e.g. `transmission:joint=2,harmonic=2,cos=0.001,sin=0`
/// (joints and links 1-based on the command line; angles in radians, lengths in model units).
/// Types: encoder_scale (scale), transmission (harmonic, cos, sin), gravity_compliance
/// (compliance), link_bending (link, compliance), bump (centre=a;b;..., width, dx, dy, dz),
/// dead_zone (width), thermal (dx, dy, dz per row), drift (sd, length in rows). Unknown and
/// repeated keys are refused.
pub fn parse_effect(spec: &str, n_joints: usize) -> Result<InjectedEffect, EffectSpecError> {
    parse_effect_of(KINDS, spec, n_joints)
}

/// [`parse_effect`] with the library's effect kinds `kinds` (the `--effect` types are those with
/// a model-file entry).
pub fn parse_effect_of(kinds: &[Kind], spec: &str, n_joints: usize) -> Result<InjectedEffect, EffectSpecError> {
    let (kind, s) = Spec::parse(spec, n_joints)?;
    let effect = parse_spec_of(kinds, &kind, &s, n_joints)?;
    // Every key given must have been read: a misspelt key is not silently ignored.
    s.check_all_read()?;
    Ok(effect)
}

fn parse_spec_of(kinds: &[Kind], kind: &str, s: &Spec, n_joints: usize) -> Result<InjectedEffect, EffectSpecError> {
    if let Some(effect) = kinds.iter().filter(|k| k.name() == kind).find_map(|k| k.parse_spec(s)) {
        return Ok(InjectedEffect::Library(effect?));
    }
    // A width is a distance: positive for a bump's, not negative for a dead zone's.
    let width = |positive: bool| -> Result<f64, EffectSpecError> {
        let w = s.number("width", None)?;
        match (positive, w) {
            (true, w) if w <= 0.0 => Err(s.bad(format!("width = {} must be positive", crate::error::number(w)))),
            (false, w) if w < 0.0 => Err(s.bad(format!("width = {} must not be negative", crate::error::number(w)))),
            _ => Ok(w),
        }
    };
    let effect = match kind {
        "bump" => {
            let centre: Result<Vec<f64>, EffectSpecError> = s
                .get("centre")
                .ok_or_else(|| s.bad("missing centre=q1;q2;...".to_string()))?
                .split(';')
                .map(|v| {
                    let x = v.trim().parse::<f64>().ok().filter(|x| x.is_finite());
                    let x = x.ok_or_else(|| s.bad(format!("bad centre value `{}`", crate::error::excerpt(v))))?;
                    crate::effects::check_effect_value("centre", x).map(|()| x).map_err(|e| s.bad(e.to_string()))
                })
                .collect();
            let centre = centre?;
            if centre.len() != n_joints {
                return Err(s.bad(format!("centre needs {n_joints} values")));
            }
            InjectedEffect::Bump {
                centre,
                width: width(true)?,
                amplitude: [s.number("dx", Some(0.0))?, s.number("dy", Some(0.0))?, s.number("dz", Some(0.0))?],
            }
        }
        "dead_zone" => InjectedEffect::DeadZone { joint: s.index("joint")?, width: width(false)? },
        "thermal" => {
            InjectedEffect::ThermalDrift { per_row: [s.number("dx", Some(0.0))?, s.number("dy", Some(0.0))?, s.number("dz", Some(0.0))?] }
        }
        "drift" => {
            let (sd, length) = (s.number("sd", None)?, s.number("length", None)?);
            if sd < 0.0 {
                return Err(s.bad(format!("sd = {} must not be negative", crate::error::number(sd))));
            }
            if length <= 0.0 {
                return Err(s.bad(format!("length = {} must be positive (rows)", crate::error::number(length))));
            }
            InjectedEffect::Drift { sd, length }
        }
        other => {
            let mut names: Vec<&str> = kinds.iter().filter(|k| !k.file_fields().is_empty()).map(|k| k.name()).collect();
            names.extend(["bump", "dead_zone", "thermal", "drift"]);
            return Err(s.bad(format!("unknown type `{other}` ({})", names.join(", "))));
        }
    };
    Ok(effect)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn planar_gravity_torque_matches_the_hand_formula() {
        // RR arm, g = −y, unit masses at the link ends: V = −(l1 s1 + l1 s1 + l2 s12),
        // τ1 = −(2 l1 c1 + l2 c12), τ2 = −l2 c12.
        let arm = EffectArm::new(cbd_protocol::NominalModel::planar(&[1.0, 0.5]).unwrap());
        let q = [0.7, -1.9];
        let tau = gravity_torques_numerical(&arm.rigid, &arm.gravity, &q);
        let c1 = q[0].cos();
        let c12 = (q[0] + q[1]).cos();
        assert!((tau[0] + 2.0 * c1 + 0.5 * c12).abs() < 1e-9, "{tau:?}");
        assert!((tau[1] + 0.5 * c12).abs() < 1e-9, "{tau:?}");
    }

    #[test]
    fn transmission_moves_the_joint_by_the_stated_angle() {
        let arm = EffectArm::new(cbd_protocol::NominalModel::planar(&[1.0, 0.5]).unwrap()).with(Effect::Transmission {
            joint: 1,
            harmonic: 2,
            cos: 0.01,
            sin: -0.02,
        });
        let q = [0.3, 1.1];
        let d = arm.deflection(&q);
        assert_eq!(d[0], 0.0);
        assert!((d[1] - (0.01 * 2.2f64.cos() - 0.02 * 2.2f64.sin())).abs() < 1e-15);
        let p = arm.position(&q, 0);
        let t = 0.3 + 1.1 + d[1];
        assert!((p[0] - (0.3f64.cos() + 0.5 * t.cos())).abs() < 1e-14);
    }

    #[test]
    fn bending_of_a_horizontal_link_is_along_gravity() {
        let arm = EffectArm::new(cbd_protocol::NominalModel::planar(&[1.0, 0.5]).unwrap())
            .with(Effect::LinkBending { link: 0, compliance: 0.01 });
        let rigid = forward_kinematics(&arm.rigid, &[0.0, 0.4]).position;
        let p = arm.position(&[0.0, 0.4], 0);
        assert!((p[0] - rigid[0]).abs() < 1e-15 && (p[1] - rigid[1] + 0.01).abs() < 1e-15);
        // A vertical link does not bend.
        let p = arm.position(&[std::f64::consts::FRAC_PI_2, 0.4], 0);
        let rigid = forward_kinematics(&arm.rigid, &[std::f64::consts::FRAC_PI_2, 0.4]).position;
        assert!((p[0] - rigid[0]).abs() < 1e-15 && (p[1] - rigid[1]).abs() < 1e-15);
    }

    #[test]
    fn parses_effect_specs() {
        let e = parse_effect("transmission:joint=2,harmonic=2,cos=0.001", 2).unwrap();
        assert_eq!(e, InjectedEffect::from(Effect::Transmission { joint: 1, harmonic: 2, cos: 0.001, sin: 0.0 }));
        assert!(parse_effect("transmission:joint=3,harmonic=2", 2).is_err());
        assert!(parse_effect("wobble:joint=1", 2).is_err());
        let b = parse_effect("bump:centre=1;2,width=0.3,dy=0.01", 2).unwrap();
        assert!(!b.in_library());
    }

    /// Issue 27 item 11: `cbd simulate` injected what a model file may not declare (effect sizes of
    /// 1e300, `encoder_scale` 1e300, a dead zone of width −1) and wrote CSVs `cbd` cannot read.
    #[test]
    fn injected_effects_obey_the_model_files_limits() {
        for (spec, reason) in [
            ("transmission:joint=1,harmonic=1,cos=1e300", "cos = 1e300 is beyond ±1e100"),
            ("encoder_scale:joint=1,scale=1e300", "scale = 1e300 is beyond ±1e100"),
            ("encoder_scale:joint=1,scale=1.5", "an encoder scale error must lie within (-1, 1)"),
            ("dead_zone:joint=1,width=-1", "width = -1 must not be negative"),
            ("bump:centre=1;2,width=0,dy=0.01", "width = 0 must be positive"),
            ("bump:centre=1e300;2,width=1,dy=0.01", "centre = 1e300 is beyond ±1e100"),
            ("thermal:dx=1e101", "dx = 1e101 is beyond ±1e100"),
        ] {
            let e = parse_effect(spec, 2).unwrap_err().to_string();
            assert!(e.contains(reason), "{spec}: {e}");
        }
        assert!(parse_effect("dead_zone:joint=1,width=0", 2).is_ok());
    }
}

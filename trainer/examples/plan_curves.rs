//! Issue 28's measurement of `cbd plan`: learning curves of dh+cbd (Euler × 1) on planned against
//! uniformly random poses, planned and random in the same run, and the error the plan predicted
//! against the error reached (RMS against the true positions at 1000 fresh random configurations).
//!
//! The planned poses come in batches as a user would measure them: the first batch from the stated
//! prior, each later one from `--data` = every pose measured so far (CbD's evidence re-estimated on
//! them, the posterior conditioned on them). "predicted" is the error the plan predicted for the
//! batch's last pose before it was measured; "after" what `cbd plan --data` reports once it is.
//!
//! ```sh
//! cargo run --release -p cbd-trainer --example plan_curves -- [six|rr|both] [seeds, e.g. 1,2,3,4,5]
//! ```
//! `CBD_PLAN_WORKSPACE` / `CBD_PLAN_CANDIDATES` / `CBD_PLAN_SPACE_FILLING` override the planner's options,
//! `CBD_PLAN_RANDOM_EVERY` makes every so-many-th pose a uniform random one, `CBD_PLAN_BATCH` caps the poses per plan (re-estimated in between), `CBD_PLAN_ORACLE=1` plans with
//! the evidence on 400 further random poses,
//! `CBD_PLAN_EXCHANGE` sets the exchange passes after each greedy batch (`CBD_PLAN_EXCHANGE_WORKSPACE`:
//! scored on a fresh workspace sample of that size per pass), `CBD_PLAN_MAX_K` ends the curves early.
//! `CBD_PLAN_MAXIMIN=1` plans with `--criterion maximin` (model-free space filling in joint angle).

use cbd_protocol::{IntegratorMethod, NominalModel};
use cbd_trainer::calibrate::{calibrate, Geometry, Settings};
use cbd_trainer::data::Measurements;
use cbd_trainer::plan::{candidates, plan, prior, Criterion, PlanInput, PlanOptions};
use cbd_trainer::simulate::six_joint::{random_configurations, SixJointRobot};
use cbd_trainer::simulate::{add_noise, configurations, rr, Sampling};
use std::f64::consts::PI;

/// A simulated arm: nominal model, joint limits, the truth and a noisy measurement.
struct Arm {
    name: &'static str,
    nominal: NominalModel,
    limits: Vec<[f64; 2]>,
    noise: f64,
    truth: Box<dyn Fn(&[f64]) -> Vec<f64>>,
    /// Uniform random configurations within the limits (count, seed).
    random: Box<dyn Fn(usize, u64) -> Vec<f64>>,
    /// Batch ends of the planned poses (the curve's K).
    sizes: Vec<usize>,
}

impl Arm {
    fn six() -> Arm {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../examples/ur5/simulated-six.toml");
        let file = cbd_trainer::data::model_file::load_model_file(path).unwrap();
        let limits = file.column_spec().unwrap().joint_limits;
        // `cbd simulate --robot six --noise 0.02`.
        let mut robot = SixJointRobot::ur5_like(1);
        robot.noise_std = 0.02;
        Arm {
            name: "six",
            nominal: file.nominal,
            limits,
            noise: 0.02,
            truth: Box::new(move |q| robot.true_position(q).to_vec()),
            random: Box::new(random_configurations),
            sizes: vec![20, 30, 40, 60, 90, 120, 160, 200],
        }
    }

    fn rr() -> Arm {
        // `cbd simulate` (RR): uniform on the torus; σ = 1e-4.
        let real = rr::RealRr::default();
        Arm {
            name: "rr",
            nominal: rr::nominal(),
            limits: vec![[0.0, 2.0 * PI]; 2],
            noise: 1e-4,
            truth: Box::new(move |q| real.position(q).to_vec()),
            random: Box::new(|count, seed| configurations(Sampling::Uniform { count, seed }, 2)),
            sizes: vec![8, 16, 24, 32, 48, 64, 96, 128],
        }
    }

    fn measure(&self, joints: &[f64], seed: u64) -> Measurements {
        let (n, m) = (self.nominal.n_joints(), self.nominal.task_dim());
        let mut positions: Vec<f64> = joints.chunks_exact(n).flat_map(|q| (self.truth)(q)).collect();
        add_noise(&mut positions, self.noise, seed);
        Measurements {
            n_joints: n,
            task_dim: m,
            joints: joints.to_vec(),
            positions,
            points_per_pose: 1,
            order: cbd_trainer::data::RowOrder::Measured,
        }
    }

    /// RMS error against the truth at `test` of what `cbd fit` writes (Euler × 1) fitted on `data`:
    /// its geometry chosen by the evidence (a planar arm: the nominal, its blob holds lengths only).
    fn reached(&self, data: &Measurements, test: &[f64]) -> f64 {
        let (n, m) = (self.nominal.n_joints(), self.nominal.task_dim());
        let settings = Settings { integrator: Some(IntegratorMethod::Euler), steps: Some(1), ..Default::default() };
        let cal = calibrate(&self.nominal, data, &settings).expect("fit");
        let got = cbd_trainer::predict::evaluate_blob(&cal.fit.blob, test).unwrap();
        let count = test.len() / n;
        let se: f64 = test
            .chunks_exact(n)
            .zip(got.chunks_exact(m))
            .map(|(q, y)| (self.truth)(q).iter().zip(y).map(|(t, y)| (t - y).powi(2)).sum::<f64>())
            .sum();
        (se / count as f64).sqrt()
    }
}

fn env_usize(name: &str, default: usize) -> usize {
    std::env::var(name).ok().and_then(|v| v.parse().ok()).unwrap_or(default)
}

struct Row {
    k: usize,
    planned: f64,
    random: f64,
    predicted: Option<f64>,
    after: Option<f64>,
}

fn run(arm: &Arm, seed: u64) -> Vec<Row> {
    let n = arm.nominal.n_joints();
    let test = (arm.random)(1000, 1000 + seed);
    // `salt`: 0 for the first plan of a curve point (the seeds of one batch per point), else distinct.
    let options = |count: usize, salt: u64| PlanOptions {
        count,
        candidates: env_usize("CBD_PLAN_CANDIDATES", 10_000),
        workspace: env_usize("CBD_PLAN_WORKSPACE", PlanOptions::default().workspace),
        space_filling: env_usize("CBD_PLAN_SPACE_FILLING", 0),
        random_every: env_usize("CBD_PLAN_RANDOM_EVERY", 0),
        exchange: env_usize("CBD_PLAN_EXCHANGE", 0),
        exchange_workspace: env_usize("CBD_PLAN_EXCHANGE_WORKSPACE", 0),
        criterion: if env_usize("CBD_PLAN_MAXIMIN", 0) > 0 { Criterion::Maximin } else { Criterion::Variance },
        seed: seed * 1000 + count as u64 + salt * 1_000_000,
        ..PlanOptions::default()
    };
    let sample = candidates::uniform_within(&arm.limits, 500, seed);
    let reach = candidates::reach(&arm.nominal, &sample);
    let stated = prior::stated(&arm.nominal, &sample, reach, prior::StatedPrior { error: 3e-4 * reach, noise: arm.noise });
    let random = (arm.random)(*arm.sizes.last().unwrap(), 200 + seed);
    let random_data = arm.measure(&random, 300 + seed);
    // CBD_PLAN_ORACLE=1: every plan with the evidence on 400 further random poses (the hyperparameters
    // a user cannot know), to see what the estimates cost.
    let oracle = (env_usize("CBD_PLAN_ORACLE", 0) > 0).then(|| {
        let q = (arm.random)(400, 700 + seed);
        prior::from_measurements(&arm.nominal, &arm.measure(&q, 800 + seed)).expect("evidence")
    });
    // The geometry planned for: the calibrated one before any pose (the stated prior), then what
    // `cbd fit` would choose on the poses measured so far.
    // CBD_PLAN_BATCH=b: at most b poses per `cbd plan` (re-estimated in between); default: one
    // batch per curve point.
    let batch_max = env_usize("CBD_PLAN_BATCH", usize::MAX);
    let mut measured: Option<Measurements> = None;
    let mut rows = Vec::new();
    let mut sub = 0u64;
    for (b, &k) in arm.sizes.iter().enumerate() {
        let mut predicted = None;
        let mut seconds = 0.0;
        let mut identified = None;
        let mut swaps = 0;
        while measured.as_ref().map_or(0, |d| d.len()) < k {
            let have = measured.as_ref().map_or(0, |d| d.len());
            let (hyperparameters, geometry) = match (&oracle, &measured) {
                (Some((h, g)), _) => (h.clone(), g.chosen),
                (None, Some(d)) => prior::from_measurements(&arm.nominal, d).map(|(h, g)| (h, g.chosen)).expect("evidence"),
                (None, None) => (stated.clone(), Geometry::Calibrated),
            };
            let input = PlanInput {
                nominal: &arm.nominal,
                limits: &arm.limits,
                to_model: None,
                user_candidates: &[],
                measured: measured.as_ref(),
                hyperparameters,
                geometry,
            };
            let count = (k - have).min(batch_max);
            let t = std::time::Instant::now();
            let first = have == arm.sizes[..b].last().copied().unwrap_or(0);
            let planned = plan(&input, &options(count, if first { 0 } else { 1 + sub })).expect("plan");
            seconds += t.elapsed().as_secs_f64();
            predicted = planned.poses.last().and_then(|p| p.predicted_rms);
            identified = planned.geometric_identified_after;
            swaps += planned.exchange_swaps;
            let joints: Vec<f64> = planned.poses.iter().flat_map(|p| p.joints.clone()).collect();
            // The first sub-batch of each curve point keeps the seed it had with one batch per point.
            let noise_seed = if first { 50 + 100 * seed + b as u64 } else { 10_000 + 100 * seed + sub };
            sub += 1;
            let batch = arm.measure(&joints, noise_seed);
            measured = Some(match measured.take() {
                Some(mut d) => {
                    d.joints.extend_from_slice(&batch.joints);
                    d.positions.extend_from_slice(&batch.positions);
                    d
                }
                None => batch,
            });
        }
        let all = measured.clone().expect("measured");
        // What `cbd plan --data` reports on all of them (count 0).
        let (h, g) = prior::from_measurements(&arm.nominal, &all).expect("evidence");
        let input = PlanInput {
            nominal: &arm.nominal,
            limits: &arm.limits,
            to_model: None,
            user_candidates: &[],
            measured: Some(&all),
            hyperparameters: h,
            geometry: g.chosen,
        };
        let after = plan(&input, &PlanOptions { count: 0, candidates: 0, ..options(0, 0) }).expect("plan").measured_predicted_rms;
        let p = arm.reached(&all, &test);
        let rd = Measurements {
            n_joints: n,
            task_dim: random_data.task_dim,
            joints: random_data.joints[..k * n].to_vec(),
            positions: random_data.positions[..k * random_data.task_dim].to_vec(),
            points_per_pose: 1,
            order: cbd_trainer::data::RowOrder::Measured,
        };
        let r = arm.reached(&rd, &test);
        eprintln!(
            "{} seed {seed} K {k:>3}: planned {p:.3e} random {r:.3e} predicted {} after {} (plan {seconds:.1} s, identified after {:?}, {swaps} exchanges)",
            arm.name,
            predicted.map_or("–".into(), |v| format!("{v:.3e}")),
            after.map_or("–".into(), |v| format!("{v:.3e}")),
            identified,
        );
        rows.push(Row { k, planned: p, random: r, predicted, after });
    }
    rows
}

/// The random count whose error equals `error` (log-log interpolation on the random curve; `None`
/// beyond its ends).
fn random_equivalent(rows: &[Row], error: f64) -> Option<f64> {
    rows.windows(2).find_map(|w| {
        let (a, b) = (&w[0], &w[1]);
        let (lo, hi) = (a.random.min(b.random), a.random.max(b.random));
        if !(lo <= error && error <= hi) {
            return None;
        }
        let t = if hi > lo { (error.ln() - a.random.ln()) / (b.random.ln() - a.random.ln()) } else { 0.0 };
        Some(((a.k as f64).ln() * (1.0 - t) + t * (b.k as f64).ln()).exp())
    })
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let which = args.get(1).map_or("both", |s| s.as_str());
    let seeds: Vec<u64> = args.get(2).map_or(vec![1, 2, 3, 4, 5], |s| s.split(',').filter_map(|v| v.parse().ok()).collect());
    let mut arms: Vec<Arm> = match which {
        "six" => vec![Arm::six()],
        "rr" => vec![Arm::rr()],
        _ => vec![Arm::rr(), Arm::six()],
    };
    // CBD_PLAN_MAX_K: stop the curves there (a quicker look).
    let max_k = env_usize("CBD_PLAN_MAX_K", usize::MAX);
    arms.iter_mut().for_each(|a| a.sizes.retain(|k| *k <= max_k));
    for arm in &arms {
        let results: Vec<(u64, Vec<Row>)> = seeds.iter().map(|&s| (s, run(arm, s))).collect();
        println!("\n{} arm (noise {}), RMS error against the truth at 1000 fresh configurations, dh+cbd Euler × 1", arm.name, arm.noise);
        println!("| seed | K | planned | random | planned = random at K_r | predicted (before) | /actual | after measuring | /actual |");
        println!("|---:|---:|---:|---:|---:|---:|---:|---:|---:|");
        for (s, rows) in &results {
            for r in rows {
                let eq = random_equivalent(rows, r.planned).map_or(
                    if r.planned < rows.last().unwrap().random { format!("> {}", rows.last().unwrap().k) } else { "–".into() },
                    |v| format!("{v:.0}"),
                );
                let f = |v: Option<f64>| v.map_or("–".to_string(), |v| format!("{v:.3e}"));
                let ratio = |v: Option<f64>| v.map_or("–".to_string(), |v| format!("{:.2}", v / r.planned));
                println!(
                    "| {s} | {} | {:.3e} | {:.3e} | {eq} | {} | {} | {} | {} |",
                    r.k,
                    r.planned,
                    r.random,
                    f(r.predicted),
                    ratio(r.predicted),
                    f(r.after),
                    ratio(r.after)
                );
            }
        }
        // Summary: geometric means over the seeds.
        let gm = |v: Vec<f64>| (v.iter().map(|x| x.ln()).sum::<f64>() / v.len() as f64).exp();
        println!("\n{} summary (geometric mean over seeds {seeds:?}):", arm.name);
        println!("| K | planned | random | planned/random |");
        println!("|---:|---:|---:|---:|");
        for i in 0..arm.sizes.len() {
            let p = gm(results.iter().map(|(_, r)| r[i].planned).collect());
            let r = gm(results.iter().map(|(_, r)| r[i].random).collect());
            println!("| {} | {p:.3e} | {r:.3e} | {:.2} |", arm.sizes[i], p / r);
        }
        let ratios: Vec<f64> = results
            .iter()
            .flat_map(|(_, rows)| rows.iter().filter(|r| r.k >= 30).filter_map(|r| r.predicted.map(|p| p / r.planned)))
            .collect();
        let after: Vec<f64> =
            results.iter().flat_map(|(_, rows)| rows.iter().filter(|r| r.k >= 30).filter_map(|r| r.after.map(|p| p / r.planned))).collect();
        let range = |v: &[f64]| {
            (
                v.iter().cloned().fold(f64::INFINITY, f64::min),
                v.iter().cloned().fold(0.0, f64::max),
                v.iter().filter(|x| **x <= 1.5 && **x >= 1.0 / 1.5).count(),
                v.len(),
            )
        };
        let (lo, hi, within, total) = range(&ratios);
        println!("predicted (before measuring) / actual, K ≥ 30: {lo:.2} – {hi:.2}, within 1.5× in {within} of {total}");
        let (lo, hi, within, total) = range(&after);
        println!("predicted (after measuring) / actual, K ≥ 30: {lo:.2} – {hi:.2}, within 1.5× in {within} of {total}");
    }
}

//! Host-side simulation of the firmware's control loop (issue 5): a fixed-rate loop that, in every
//! cycle, reads the joint configuration of a moving trajectory, evaluates the calibrated model
//! (position and Jacobian) and must finish before the next tick.
//!
//! ```text
//! cbd-control-loop [BLOB] [--rate HZ] [--seconds S] [--strict] [--cartesian]
//! ```
//!
//! With `--cartesian` (issue 15) the loop follows a Cartesian path instead: every tick it turns the
//! path's next target into a joint command with `Calibrator::compensate`, seeded with the previous
//! tick's command. The path is the calibrated tool position along the joint trajectory below
//! (reachable by construction; computed before the loop); it reports compensation times, the
//! largest residual |k1(q) − target| and the ticks whose target was not reached.
//!
//! Without BLOB it uses the 256-point RR grid blob of the firmware check with the scheme `cbd demo` trains
//! (Euler × 2; pass a blob from `cbd demo --out FILE` for a trained model).
//! It reports evaluation times (worst, p99, median, mean), the worst lateness of a cycle's start,
//! the deadline misses (a cycle whose evaluation ends after the next tick) and the ticks skipped
//! because the loop was not scheduled for a whole period. The trajectory is a
//! function of the cycle index, not of wall time, so the evaluated values (and their checksum) are
//! deterministic; only the timings depend on the machine. With `--strict` the exit status is 2 when
//! any deadline was missed (a host OS is no real-time system: expect misses on a busy machine).

use cbd_runtime::{storage_len_for, Calibrator};
use std::process::ExitCode;
use std::time::{Duration, Instant};

#[path = "../../fw-host/src/blobs.rs"]
#[allow(dead_code)]
mod blobs;
#[path = "../../firmware/src/shared.rs"]
#[allow(dead_code)]
mod shared;

struct Args {
    blob: Option<String>,
    rate_hz: f64,
    seconds: f64,
    strict: bool,
    cartesian: bool,
}

fn parse_args() -> Result<Args, String> {
    let mut args = Args { blob: None, rate_hz: 1000.0, seconds: 2.0, strict: false, cartesian: false };
    let mut it = std::env::args().skip(1);
    while let Some(a) = it.next() {
        let mut value = |name: &str| it.next().ok_or(format!("{name} needs a value"))?.parse::<f64>().map_err(|e| format!("{name}: {e}"));
        match a.as_str() {
            "--rate" => args.rate_hz = value("--rate")?,
            "--seconds" => args.seconds = value("--seconds")?,
            "--strict" => args.strict = true,
            "--cartesian" => args.cartesian = true,
            "-h" | "--help" => return Err("usage: cbd-control-loop [BLOB] [--rate HZ] [--seconds S] [--strict] [--cartesian]".into()),
            _ if args.blob.is_none() && !a.starts_with('-') => args.blob = Some(a),
            _ => return Err(format!("unexpected argument {a}")),
        }
    }
    if !(args.rate_hz > 0.0 && args.seconds > 0.0) {
        return Err("--rate and --seconds must be positive".into());
    }
    Ok(args)
}

/// The joint trajectory at time t (seconds): smooth, sweeping much of the workspace.
fn trajectory(t: f64, q: &mut [f64]) {
    for (d, qd) in q.iter_mut().enumerate() {
        let f = 0.25 + 0.15 * d as f64; // Hz
        let phase = 0.7 * d as f64;
        *qd = 0.4 * d as f64 + 2.5 * (2.0 * std::f64::consts::PI * f * t + phase).sin();
    }
}

fn percentile(sorted: &[Duration], p: f64) -> Duration {
    let i = ((sorted.len() as f64 - 1.0) * p).round() as usize;
    sorted[i.min(sorted.len() - 1)]
}

fn run(args: &Args) -> Result<bool, String> {
    let blob = match &args.blob {
        Some(path) => std::fs::read(path).map_err(|e| format!("{path}: {e}"))?,
        None => blobs::rr_grid_blob(16, 0x0000_0100, blobs::DEMO_SCHEME),
    };
    let model = cbd_protocol::decode(&blob).map_err(|e| e.to_string())?;
    let n = model.n_joints();
    let len = storage_len_for(&model);
    // All allocation happens before the loop: the loop itself, like the firmware, allocates nothing.
    let mut storage = vec![0.0; len];
    let load_start = Instant::now();
    let mut cal = Calibrator::load(&blob, &mut storage).map_err(|e| e.to_string())?;
    let load_time = load_start.elapsed();

    let period = Duration::from_secs_f64(1.0 / args.rate_hz);
    let cycles = (args.seconds * args.rate_hz).round() as usize;
    let mut eval_times = Vec::with_capacity(cycles);
    let mut misses = 0usize;
    let mut skipped = 0usize;
    let mut worst_lateness = Duration::ZERO;
    let mut errors = 0usize;
    let mut checksum = 0u64;
    let mut q = vec![0.0; n];
    // --cartesian: the path's targets (m per tick), the previous command, the largest residual.
    let m = model.task_dim();
    let mut targets = Vec::new();
    if args.cartesian {
        targets.reserve(cycles * m);
        for k in 0..cycles {
            trajectory(k as f64 / args.rate_hz, &mut q);
            let e = cal.evaluate(&q).map_err(|e| format!("path tick {k}: {e}"))?;
            targets.extend(e.position().iter());
        }
        trajectory(0.0, &mut q);
        for qd in q.iter_mut() {
            *qd += 0.05;
        }
    }
    let mut command = vec![0.0; n];
    let (mut worst_residual, mut not_reached) = (0.0f64, 0usize);
    let start = Instant::now();
    let mut k = 0usize;
    while k < cycles {
        // A loop that fell behind by whole periods (the OS did not run it) skips those ticks,
        // as a controller's overrun handling would, instead of running them back to back.
        let behind = ((Instant::now() - start).as_secs_f64() * args.rate_hz) as usize;
        if behind > k {
            skipped += behind - k;
            k = behind;
            if k >= cycles {
                break;
            }
        }
        let release = start + period * k as u32;
        let deadline = release + period;
        // Wait for the tick: sleep most of the way, then spin for precision.
        loop {
            let now = Instant::now();
            if now >= release {
                worst_lateness = worst_lateness.max(now - release);
                break;
            }
            let left = release - now;
            if left > Duration::from_micros(200) {
                std::thread::sleep(left - Duration::from_micros(150));
            } else {
                std::hint::spin_loop();
            }
        }
        let t1 = if args.cartesian {
            // q holds the previous tick's command: the seed.
            let target = &targets[k * m..(k + 1) * m];
            let t0 = Instant::now();
            let result = cal.compensate(std::hint::black_box(target), &q, &mut command);
            let t1 = Instant::now();
            eval_times.push(t1 - t0);
            match result {
                Ok(c) => {
                    worst_residual = worst_residual.max(c.residual);
                    not_reached += usize::from(!c.reached);
                    for v in command.iter().chain([c.residual].iter()) {
                        checksum = checksum.rotate_left(5) ^ v.to_bits();
                    }
                    q.copy_from_slice(&command);
                }
                Err(_) => errors += 1,
            }
            t1
        } else {
            trajectory(k as f64 / args.rate_hz, &mut q);
            let t0 = Instant::now();
            let result = cal.evaluate(std::hint::black_box(&q));
            let t1 = Instant::now();
            eval_times.push(t1 - t0);
            match result {
                Ok(e) => {
                    for v in e.position().iter().chain(e.jacobian().iter()) {
                        checksum = checksum.rotate_left(5) ^ v.to_bits();
                    }
                }
                Err(_) => errors += 1,
            }
            t1
        };
        if t1 > deadline {
            misses += 1;
        }
        k += 1;
    }
    let total = start.elapsed();
    let mut sorted = eval_times.clone();
    sorted.sort();
    let evaluated = eval_times.len();
    let mean = eval_times.iter().sum::<Duration>() / evaluated.max(1) as u32;
    println!(
        "control loop: {} points, {} joints, {:?} × {} steps; load {:.1} ms",
        model.n_points,
        n,
        model.integrator.method,
        model.integrator.steps,
        load_time.as_secs_f64() * 1e3
    );
    println!(
        "rate {:.0} Hz, {cycles} ticks in {:.3} s (period {:.0} µs): {evaluated} evaluated, {skipped} skipped (loop not scheduled in time)",
        args.rate_hz,
        total.as_secs_f64(),
        period.as_secs_f64() * 1e6
    );
    if args.cartesian {
        println!("Cartesian path: compensate every tick; largest residual {worst_residual:.3e}, {not_reached} ticks not reached");
    }
    println!(
        "{} time: worst {:.1} µs, p99 {:.1} µs, median {:.1} µs, mean {:.1} µs, best {:.1} µs",
        if args.cartesian { "compensation" } else { "evaluation" },
        us(sorted.last().copied().unwrap_or_default()),
        us(percentile(&sorted, 0.99)),
        us(percentile(&sorted, 0.5)),
        us(mean),
        us(sorted.first().copied().unwrap_or_default())
    );
    println!("worst start lateness {:.1} µs; deadline misses {misses} of {evaluated}; evaluation errors {errors}", us(worst_lateness));
    println!("result checksum {checksum:016x} (deterministic when no tick was skipped: blob and trajectory only)");
    Ok(errors == 0 && (misses + skipped == 0 || !args.strict))
}

fn us(d: Duration) -> f64 {
    d.as_secs_f64() * 1e6
}

fn main() -> ExitCode {
    match parse_args().and_then(|a| run(&a)) {
        Ok(true) => ExitCode::SUCCESS,
        Ok(false) => {
            eprintln!("cbd-control-loop: deadline misses or evaluation errors (see above)");
            ExitCode::from(2)
        }
        Err(e) => {
            eprintln!("cbd-control-loop: {e}");
            ExitCode::FAILURE
        }
    }
}

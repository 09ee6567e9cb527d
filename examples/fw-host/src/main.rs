//! Host side of the firmware check (issue 5).
//!
//! ```text
//! cbd-fw-host make-blobs OUT_DIR   # rr.blob, six.blob, six-effects.blob (Heun × 5), rr64/rr256/rr1024.blob (Euler × 2),
//!                                  # rr-ws.blob (Euler × 1), six-ws.blob (Heun × 2): the fields in the kernels' own basis (format 5),
//!                                  # chain10.blob (10 joints, Heun × 2), six-points.blob (3 tool points, format 6),
//!                                  # six-c.blob (the configuration-dependent task field, format 8, Euler × 1) and
//!                                  # six-e1.blob (the same model without it)
//! cbd-fw-host eval BLOB            # the result lines the firmware prints, from the host runtime
//! cbd-fw-host eval --transported BLOB  # the same with evaluate_transported (firmware feature `transported`)
//! cbd-fw-host info BLOB            # n_points n_joints task_dim storage_len_for blob_bytes
//! cbd-fw-host time BLOB            # host ns per evaluation (exact and transported Jacobian)
//! cbd-fw-host accuracy BLOB CSV    # position error against measured rows (joints…, position…)
//! ```
//!
//! Blobs are deterministic: the same bytes on every run and machine.

use cbd_protocol::*;
use cbd_runtime::{storage_len_for, Calibrator};
use std::path::Path;
use std::process::ExitCode;

mod blobs;
#[path = "../../firmware/src/shared.rs"]
mod shared;
use blobs::{
    chain10_blob, rr_grid_blob, rr_reference_blob, rr_ws_blob, six_configuration_blob, six_effects_blob, six_euler1_blob, six_joint_blob,
    six_tool_points_blob, six_ws_blob, DEMO_SCHEME,
};

fn make_blobs(out_dir: &Path) -> Result<(), String> {
    std::fs::create_dir_all(out_dir).map_err(|e| format!("{}: {e}", out_dir.display()))?;
    for (name, blob) in [
        ("rr.blob", rr_reference_blob()),
        ("six.blob", six_joint_blob()),
        ("six-effects.blob", six_effects_blob()),
        ("rr64.blob", rr_grid_blob(8, 0x0000_0064, DEMO_SCHEME)),
        ("rr256.blob", rr_grid_blob(16, 0x0000_0100, DEMO_SCHEME)),
        ("rr1024.blob", rr_grid_blob(32, 0x0000_0400, DEMO_SCHEME)),
        ("rr-ws.blob", rr_ws_blob()),
        ("six-ws.blob", six_ws_blob()),
        ("chain10.blob", chain10_blob()),
        ("six-points.blob", six_tool_points_blob()),
        ("six-c.blob", six_configuration_blob()),
        ("six-e1.blob", six_euler1_blob()),
    ] {
        let path = out_dir.join(name);
        std::fs::write(&path, &blob).map_err(|e| format!("{}: {e}", path.display()))?;
        println!("{} {} bytes", path.display(), blob.len());
    }
    Ok(())
}

fn read_blob(path: &Path) -> Result<Vec<u8>, String> {
    std::fs::read(path).map_err(|e| format!("{}: {e}", path.display()))
}

fn needed_storage(blob: &[u8]) -> Result<(Model<'_>, usize), String> {
    let model = decode(blob).map_err(|e| e.to_string())?;
    let len = storage_len_for(&model);
    Ok((model, len))
}

fn info(path: &Path) -> Result<(), String> {
    let blob = read_blob(path)?;
    let (model, len) = needed_storage(&blob)?;
    println!("{} {} {} {} {}", model.n_points, model.n_joints(), model.task_dim(), len, blob.len());
    Ok(())
}

fn eval(path: &Path, transported: bool) -> Result<(), String> {
    let blob = read_blob(path)?;
    let (model, len) = needed_storage(&blob)?;
    let n = model.n_joints();
    let mut storage = vec![0.0; len];
    let mut cal = Calibrator::load(&blob, &mut storage).map_err(|e| e.to_string())?;
    let mut out = String::new();
    let mut q = [0.0; MAX_JOINTS];
    for i in 0..shared::COUNT {
        let q = &mut q[..n];
        shared::config(i, q);
        let result = if transported { cal.evaluate_transported(q) } else { cal.evaluate(q) };
        let written = match result {
            Ok(e) => {
                let (pos, jac) = (e.position(), e.jacobian());
                let (m, n) = jac.shape();
                shared::write_result(
                    &mut out,
                    i,
                    pos.iter().copied(),
                    (0..m).flat_map(|a| (0..n).filter_map(move |d| jac.get((a, d)).copied())),
                )
            }
            Err(_) => shared::write_error(&mut out, i),
        };
        written.map_err(|e| e.to_string())?;
        if cal.model().nominal.tool_point_count() >= 3 {
            let written = match cal.evaluate_pose(q) {
                Ok(p) => shared::write_pose(&mut out, i, &p),
                Err(_) => shared::write_pose_error(&mut out, i),
            };
            written.map_err(|e| e.to_string())?;
        }
    }
    // Compensation cases, as the firmware prints them (after its evaluations).
    let (mut seed, mut command, mut target) = ([0.0; MAX_JOINTS], [0.0; MAX_JOINTS], [0.0; cbd_runtime::MAX_TASK_DIM]);
    for i in 0..shared::COMPENSATE_COUNT {
        let (seed, command) = (&mut seed[..n], &mut command[..n]);
        let written = match shared::compensate_inputs(&mut cal, i, seed, &mut target) {
            Ok(m) => match cal.compensate(&target[..m], seed, command) {
                Ok(c) => shared::write_compensation(&mut out, i, command, &c),
                Err(_) => shared::write_compensation_error(&mut out, i),
            },
            Err(_) => shared::write_compensation_error(&mut out, i),
        };
        written.map_err(|e| e.to_string())?;
    }
    print!("{out}");
    Ok(())
}

/// Median over rounds of the mean ns per evaluation of the `COUNT` shared configurations.
fn time(path: &Path) -> Result<(), String> {
    let blob = read_blob(path)?;
    let (model, len) = needed_storage(&blob)?;
    let n = model.n_joints();
    let mut storage = vec![0.0; len];
    let mut cal = Calibrator::load(&blob, &mut storage).map_err(|e| e.to_string())?;
    let mut queries = vec![0.0; shared::COUNT * n];
    for (i, q) in queries.chunks_exact_mut(n).enumerate() {
        shared::config(i, q);
    }
    for transported in [false, true] {
        let mut rounds: Vec<f64> = (0..21)
            .map(|_| {
                let t0 = std::time::Instant::now();
                for q in queries.chunks_exact(n) {
                    let e =
                        if transported { cal.evaluate_transported(std::hint::black_box(q)) } else { cal.evaluate(std::hint::black_box(q)) };
                    std::hint::black_box(e.ok());
                }
                t0.elapsed().as_secs_f64() * 1e9 / shared::COUNT as f64
            })
            .collect();
        rounds.sort_by(f64::total_cmp);
        println!(
            "{} ns/eval (median of 21 rounds, min {:.0}): {:.0}",
            if transported { "transported" } else { "exact" },
            rounds[0],
            rounds[10]
        );
    }
    Ok(())
}

/// Position error |k1(q) − y| of the runtime (this build's scalar) over the rows of a measurement
/// CSV with a header line, joint columns then position columns (`cbd simulate` writes one).
fn accuracy(path: &Path, csv: &Path) -> Result<(), String> {
    let blob = read_blob(path)?;
    let (model, len) = needed_storage(&blob)?;
    let (n, m) = (model.n_joints(), model.task_dim());
    let mut storage = vec![0.0; len];
    let mut cal = Calibrator::load(&blob, &mut storage).map_err(|e| e.to_string())?;
    let text = std::fs::read_to_string(csv).map_err(|e| format!("{}: {e}", csv.display()))?;
    let mut errors = Vec::new();
    for (i, line) in text.lines().enumerate().skip(1) {
        let row: Vec<f64> =
            line.split(',').map(|v| v.trim().parse::<f64>()).collect::<Result<_, _>>().map_err(|e| format!("line {}: {e}", i + 1))?;
        if row.len() != n + m {
            return Err(format!("line {}: {} values, expected {}", i + 1, row.len(), n + m));
        }
        let e = cal.evaluate(&row[..n]).map_err(|e| format!("line {}: {e}", i + 1))?;
        let err2: f64 = e.position().iter().zip(&row[n..]).map(|(a, b)| (a - b) * (a - b)).sum();
        errors.push(err2.sqrt());
    }
    errors.sort_by(f64::total_cmp);
    let count = errors.len();
    if count == 0 {
        return Err("no rows".into());
    }
    let mean = errors.iter().sum::<f64>() / count as f64;
    let p99 = errors[((count as f64 * 0.99).ceil() as usize).clamp(1, count) - 1];
    let scalar = std::mem::size_of_val(&storage[0]) * 8;
    println!("f{scalar} rows {count} mean {mean:.3e} median {:.3e} p99 {p99:.3e} max {:.3e}", errors[count / 2], errors[count - 1]);
    Ok(())
}

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().collect();
    let result = match args.iter().map(String::as_str).collect::<Vec<_>>()[1..] {
        ["make-blobs", dir] => make_blobs(Path::new(dir)),
        ["eval", blob] => eval(Path::new(blob), false),
        ["eval", "--transported", blob] => eval(Path::new(blob), true),
        ["info", blob] => info(Path::new(blob)),
        ["time", blob] => time(Path::new(blob)),
        ["accuracy", blob, csv] => accuracy(Path::new(blob), Path::new(csv)),
        _ => Err("usage: cbd-fw-host make-blobs OUT_DIR | eval [--transported] BLOB | info BLOB | time BLOB | accuracy BLOB CSV".into()),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("cbd-fw-host: {e}");
            ExitCode::FAILURE
        }
    }
}

//! Host side of the firmware check (issue 5).
//!
//! ```text
//! cbd-fw-host make-blobs OUT_DIR   # rr.blob, six.blob, rr64.blob, rr1024.blob
//! cbd-fw-host eval BLOB            # the result lines the firmware prints, from the host runtime
//! cbd-fw-host eval --transported BLOB  # the same with evaluate_transported (firmware feature `transported`)
//! cbd-fw-host info BLOB            # n_points n_joints task_dim storage_len blob_bytes
//! ```
//!
//! Blobs are deterministic: the same bytes on every run and machine.

use cbd_protocol::*;
use cbd_runtime::{storage_len, Calibrator};
use std::path::Path;
use std::process::ExitCode;

mod blobs;
#[path = "../../firmware/src/shared.rs"]
mod shared;
use blobs::{rr_grid_blob, rr_reference_blob, six_joint_blob};

fn make_blobs(out_dir: &Path) -> Result<(), String> {
    std::fs::create_dir_all(out_dir).map_err(|e| format!("{}: {e}", out_dir.display()))?;
    for (name, blob) in [
        ("rr.blob", rr_reference_blob()),
        ("six.blob", six_joint_blob()),
        ("rr64.blob", rr_grid_blob(8, 0x0000_0064)),
        ("rr1024.blob", rr_grid_blob(32, 0x0000_0400)),
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
    let len = storage_len(model.n_points as usize, model.n_joints(), model.task_dim(), model.integrator);
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
    }
    print!("{out}");
    Ok(())
}

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().collect();
    let result = match args.iter().map(String::as_str).collect::<Vec<_>>()[1..] {
        ["make-blobs", dir] => make_blobs(Path::new(dir)),
        ["eval", blob] => eval(Path::new(blob), false),
        ["eval", "--transported", blob] => eval(Path::new(blob), true),
        ["info", blob] => info(Path::new(blob)),
        _ => Err("usage: cbd-fw-host make-blobs OUT_DIR | eval [--transported] BLOB | info BLOB".into()),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("cbd-fw-host: {e}");
            ExitCode::FAILURE
        }
    }
}

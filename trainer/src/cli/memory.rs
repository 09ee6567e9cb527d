//! Memory a command will need, estimated before it allocates, against what the process may use:
//! a fit or simulation too large for the machine is refused up front with the figure and the flag
//! that lowers it (exit 1), instead of an allocation failure deep inside faer (exit 101) or an abort
//! (exit 134).

/// Bytes per f64.
const F64: f64 = 8.0;

/// Copies of the (N·m)² momentum-space matrix a fit holds at its peak (K_lin, its Cholesky factor,
/// the tangent and a work copy): 2.0 GB measured at N = 4096, m = 2 (BENCHMARKS.md) is 3.7 copies.
const FIT_MATRIX_COPIES: f64 = 4.0;

/// Bytes per simulated row per value: the f64 itself and its CSV text (`{:?}` prints up to 24
/// characters plus a separator), held together while the file is written.
const SIMULATE_BYTES_PER_VALUE: f64 = 8.0 + 26.0;

/// Estimated peak bytes of fitting `rows` measurements of `task_dim` coordinates.
pub fn fit_bytes(rows: usize, task_dim: usize) -> f64 {
    let unknowns = rows as f64 * task_dim as f64;
    FIT_MATRIX_COPIES * unknowns * unknowns * F64
}

/// Estimated peak bytes of simulating `rows` rows of `values_per_row` values.
pub fn simulate_bytes(rows: f64, values_per_row: usize) -> f64 {
    rows * values_per_row as f64 * SIMULATE_BYTES_PER_VALUE
}

/// The most rows of `task_dim` coordinates a fit can hold in `available` bytes.
pub fn max_fit_rows(available: f64, task_dim: usize) -> usize {
    ((available / (FIT_MATRIX_COPIES * F64)).sqrt() / task_dim.max(1) as f64).floor() as usize
}

/// Bytes this process may still allocate: the least of the address-space limit (`ulimit -v`),
/// the cgroup's memory limit and the machine's available memory; `None` where none is known.
pub fn available_bytes() -> Option<f64> {
    [address_space_limit(), cgroup_limit(), meminfo_available()].into_iter().flatten().reduce(f64::min)
}

fn address_space_limit() -> Option<f64> {
    let mut limit = libc::rlimit { rlim_cur: 0, rlim_max: 0 };
    // SAFETY: getrlimit writes one rlimit into the struct we own.
    let ok = unsafe { libc::getrlimit(libc::RLIMIT_AS, &mut limit) } == 0;
    (ok && limit.rlim_cur != libc::RLIM_INFINITY).then_some(limit.rlim_cur as f64)
}

fn cgroup_limit() -> Option<f64> {
    // cgroup v2 ("max" means none), then v1 (a huge number means none).
    let v2 = std::fs::read_to_string("/sys/fs/cgroup/memory.max").ok().and_then(|t| t.trim().parse::<f64>().ok());
    let v1 = std::fs::read_to_string("/sys/fs/cgroup/memory/memory.limit_in_bytes").ok().and_then(|t| t.trim().parse::<f64>().ok());
    v2.or(v1).filter(|v| *v < 1e18)
}

fn meminfo_available() -> Option<f64> {
    let text = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = text.lines().find(|l| l.starts_with("MemAvailable:"))?;
    let kib: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib * 1024.0)
}

/// Bytes as a short figure ("51.2 GB").
pub fn gigabytes(bytes: f64) -> String {
    format!("{:.1} GB", bytes / 1e9)
}

/// Refuses a fit of `rows` × `task_dim` that cannot fit in `available` bytes, naming the need,
/// what is available, how many rows would fit and `remedy` (the caller's flag that lowers it).
pub fn check_fit(rows: usize, task_dim: usize, available: Option<f64>, remedy: &str) -> Result<(), String> {
    let (Some(available), need) = (available, fit_bytes(rows, task_dim)) else { return Ok(()) };
    if need <= available {
        return Ok(());
    }
    Err(format!(
        "fitting {rows} measurements of {task_dim} coordinates needs about {} ({FIT_MATRIX_COPIES} matrices of ({rows}·{task_dim})² values), more than the {} this process may use; at most {} rows fit: {remedy}",
        gigabytes(need),
        gigabytes(available),
        max_fit_rows(available, task_dim)
    ))
}

/// `check_fit` for all rows of `data`, read from `file`, against what this process may use; the
/// error names the file.
pub fn check_fit_of(file: &std::path::Path, data: &crate::data::Measurements, remedy: &str) -> Result<(), String> {
    check_fit(data.len(), data.task_dim, available_bytes(), remedy).map_err(|e| format!("{}: {e}", file.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Issue 17 item 5: nothing checked the size up front; 20k rows under a 6 GB limit panicked
    /// inside faer (exit 101).
    #[test]
    fn memory_needed_is_estimated_before_allocating() {
        let e = check_fit(20_000, 3, Some(6e9), "--max-rows").unwrap_err();
        assert!(e.contains("needs about 115.2 GB") && e.contains("6.0 GB") && e.contains("--max-rows"), "{e}");
        let k = max_fit_rows(6e9, 3);
        assert!(check_fit(k, 3, Some(6e9), "").is_ok() && check_fit(k + 1, 3, Some(6e9), "").is_err(), "{k}");
        assert!(check_fit(4096, 2, Some(6e9), "").is_ok());
        assert!(check_fit(1_000_000, 3, None, "").is_ok());
        // What this process may use is known on Linux and positive.
        assert!(available_bytes().is_some_and(|b| b > 0.0));
    }
}

//! Memory a command will need, estimated before it allocates, against what the process may use:
//! a fit or simulation too large for the machine is refused up front with the figure and the flag
//! that lowers it (exit 1), instead of an allocation failure deep inside faer (exit 101) or an abort
//! (exit 134). The estimate counts every large allocation: the (N·m)² matrices, and per worker
//! thread faer's matrix-multiply workspace and the thread's stack.

use crate::error::Context;

/// Bytes per f64.
const F64: f64 = 8.0;

/// A computation refused up front: what it needs, what this process may use, and the flag that
/// lowers the need or the limit to raise (the message says which).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{0}")]
pub struct MemoryError(pub String);

impl From<MemoryError> for crate::Error {
    fn from(e: MemoryError) -> crate::Error {
        crate::Error::stage("memory", e)
    }
}

/// Copies of the (N·m)² momentum-space matrix a fit holds at its peak (K_lin, its Cholesky factor,
/// the tangent and a work copy): 2.0 GB measured at N = 4096, m = 2 (BENCHMARKS.md) is 3.7 copies.
const FIT_MATRIX_COPIES: f64 = 4.0;

/// What the allocator holds beyond the live blocks: the heap grows by the data plus a 64 MiB pad
/// (`solver::allocator::keep_freed_memory`); under an address-space limit, where blocks of 1 MiB and
/// more are returned when freed (`track_live_memory`), the small blocks' heap.
const ALLOCATOR_PAD: f64 = 64.0 * 1048576.0;

/// Room kept for the heap of small blocks when a later allocation is checked ([`room_for`]).
const SMALL_BLOCKS_MARGIN: f64 = 16.0 * 1048576.0;

/// Bytes per simulated row per value: the f64 itself and its CSV text (`{:?}` prints up to 24
/// characters plus a separator), held together while the file is written.
const SIMULATE_BYTES_PER_VALUE: f64 = 8.0 + 26.0;

/// Estimated peak bytes of fitting `rows` measurements of `task_dim` coordinates on `threads`
/// worker threads: the matrices, and what the threads and the allocator hold whatever the size
/// ([`fixed_fit_bytes`]).
pub fn fit_bytes(rows: usize, task_dim: usize, threads: usize) -> f64 {
    matrix_bytes(rows, task_dim) + fixed_fit_bytes(threads)
}

/// The (N·m)² matrices of a fit of `rows` × `task_dim`.
fn matrix_bytes(rows: usize, task_dim: usize) -> f64 {
    let unknowns = rows as f64 * task_dim as f64;
    FIT_MATRIX_COPIES * unknowns * unknowns * F64
}

/// What a fit on `threads` workers holds whatever its size: each worker's ([`worker_bytes`]) and the
/// allocator's pad.
pub fn fixed_fit_bytes(threads: usize) -> f64 {
    threads as f64 * worker_bytes(threads) + ALLOCATOR_PAD
}

/// One of `threads` worker threads: faer's matrix-multiply workspaces and the thread's stack. A
/// worker that waits inside a parallel multiply may start another one (rayon's work stealing), which
/// cannot borrow its thread's buffer and allocates a second: two per worker when there are several
/// (peaks of 4 × 64 MiB measured on two workers at N = 1024), one on a single worker.
pub fn worker_bytes(threads: usize) -> f64 {
    let buffers = if threads > 1 { 2.0 } else { 1.0 };
    buffers * gemm_workspace_bytes() + crate::workers::WORKER_STACK_BYTES as f64
}

/// faer's matrix-multiply workspace per thread that multiplies. faer 0.24 multiplies on x86-64
/// with private-gemm-x86, which keeps a thread-local packing buffer of two blocks of its "L3"
/// figure, rounded up to 4 KiB pages: the L3 size per sharing CPU, times the CPUs sharing an L1,
/// times the physical cores, at least 2 MiB and 4 × its L2 figure. That is 64 MiB on a 2-core
/// machine with a 32 MiB L3 and about 1 GB on a large server: more than the matrices of a small
/// fit, and independent of N, so `--max-rows` cannot lower it. The same figure bounds the portable
/// path's (L2-sized) buffers. `tests/gemm_workspace.rs` checks it against the allocation.
pub fn gemm_workspace_bytes() -> f64 {
    static BYTES: std::sync::OnceLock<f64> = std::sync::OnceLock::new();
    *BYTES.get_or_init(|| {
        let l3 = gemm_cache_sizes().map_or(CACHE_DEFAULTS[2], |c| c[2]) as f64;
        2.0 * (l3 / 4096.0).ceil() * 4096.0
    })
}

/// private-gemm-x86's defaults (bytes of L1, L2, L3) and floor for each level.
const CACHE_DEFAULTS: [usize; 3] = [32 << 10, 256 << 10, 2 << 20];

/// The cache sizes private-gemm-x86 works with, as it reads them from Linux's sysfs (`None`
/// elsewhere or when sysfs cannot be read, where it would fall back to `lscpu`).
fn gemm_cache_sizes() -> Option<[usize; 3]> {
    let mut bytes = [0usize; 3];
    let mut l1_shared = 1;
    for cpu in std::fs::read_dir("/sys/devices/system/cpu").ok()?.flatten() {
        let name = cpu.file_name();
        if !name.to_string_lossy().starts_with("cpu") || !cpu.path().join("cache").is_dir() {
            continue;
        }
        for index in std::fs::read_dir(cpu.path().join("cache")).ok()?.flatten() {
            if !index.file_name().to_string_lossy().starts_with("index") || !index.path().is_dir() {
                continue;
            }
            let read = |field: &str| std::fs::read_to_string(index.path().join(field)).ok().map(|t| t.trim().to_string());
            if !matches!(read("type").as_deref(), Some("Data" | "Unified")) {
                continue;
            }
            let (Some(level), Some(size), Some(shared)) = (
                read("level").and_then(|l| l.parse::<usize>().ok()),
                read("size").and_then(|s| cache_size(&s)),
                read("shared_cpu_list").and_then(|l| cpu_count(&l)),
            ) else {
                continue;
            };
            if !(1..=3).contains(&level) || shared == 0 {
                continue;
            }
            if level == 1 {
                l1_shared = shared;
            }
            bytes[level - 1] = size / shared;
        }
    }
    for b in &mut bytes {
        *b *= l1_shared;
    }
    bytes[2] *= physical_cores()?;
    bytes[0] = bytes[0].max(CACHE_DEFAULTS[0]);
    bytes[1] = bytes[1].max(CACHE_DEFAULTS[1]).max(4 * bytes[0]);
    bytes[2] = bytes[2].max(CACHE_DEFAULTS[2]).max(4 * bytes[1]);
    Some(bytes)
}

/// A sysfs cache size: `32768K`, `32M`, `1G` or bytes.
fn cache_size(text: &str) -> Option<usize> {
    let (digits, factor) = match text.as_bytes().last()? {
        b'K' => (&text[..text.len() - 1], 1 << 10),
        b'M' => (&text[..text.len() - 1], 1 << 20),
        b'G' => (&text[..text.len() - 1], 1 << 30),
        _ => (text, 1),
    };
    digits.parse::<usize>().ok().map(|v| v * factor)
}

/// CPUs in a sysfs list such as `0-3,8`.
fn cpu_count(list: &str) -> Option<usize> {
    list.split(',').try_fold(0, |sum, item| match item.split_once('-') {
        Some((a, b)) => Some(sum + b.parse::<usize>().ok()? + 1 - a.parse::<usize>().ok()?),
        None => item.parse::<usize>().ok().map(|_| sum + 1),
    })
}

/// Physical cores as `/proc/cpuinfo` gives them (distinct physical id and core id pairs; the
/// logical CPUs where it names none), as private-gemm-x86's `num_cpus::get_physical` counts them.
fn physical_cores() -> Option<usize> {
    let text = std::fs::read_to_string("/proc/cpuinfo").ok()?;
    let mut cores = std::collections::HashSet::new();
    let (mut physical, mut logical) = (None, 0);
    for line in text.lines() {
        let value = || line.split(':').nth(1).map(|v| v.trim().to_string());
        if line.starts_with("processor") {
            logical += 1;
        } else if line.starts_with("physical id") {
            physical = value();
        } else if line.starts_with("core id") {
            cores.insert((physical.clone(), value()));
        }
    }
    Some(if cores.is_empty() { logical.max(1) } else { cores.len() })
}

/// The linear model's least-squares problem in the expansion (`expansion::fit_linear`): the design
/// (`rows` × `weights`) and the whitened stacked matrix ((`rows` + `weights`) × `weights`) its QR
/// factors in place. Its size depends on the kernels the evidence chose, so it is checked when
/// they are known ([`room_for`]): 0.9 GB for the UR5 example's 3000 residuals and 7770 weights.
pub fn expansion_bytes(rows: usize, weights: usize) -> f64 {
    let (r, w) = (rows as f64, weights as f64);
    (r * w + (r + w) * w) * F64
}

/// A multi-step scheme fitted in weight space (`expansion::fit_flow`): the Jacobian and a trial's
/// (`rows` × `params` each) and the damped stacked matrix ((`rows` + 2 `params`) × `params`).
pub fn flow_expansion_bytes(rows: usize, params: usize) -> f64 {
    let (r, p) = (rows as f64, params as f64);
    (2.0 * r * p + (r + 2.0 * p) * p) * F64
}

/// Whether `bytes` more fit in what this process may use now, less what the workers it runs on may
/// still allocate: nothing for a single worker, whose workspace the fit's earlier factorisations
/// allocated (it is in the address space already), two workspaces each for several (one may not
/// have multiplied yet, and work stealing starts second ones), and a margin for small blocks. The
/// error gives both figures.
pub fn room_for(bytes: f64) -> Result<(), MemoryError> {
    let Some(available) = available_bytes() else { return Ok(()) };
    let workers = crate::workers::current_workers();
    let pending = if workers > 1 { 2.0 * workers as f64 * gemm_workspace_bytes() } else { 0.0 };
    let room = available - pending - SMALL_BLOCKS_MARGIN;
    if bytes <= room {
        Ok(())
    } else {
        Err(MemoryError(format!("needs about {}, more than the {} this process may use", gigabytes(bytes), gigabytes(room.max(0.0)))))
    }
}

/// Estimated peak bytes of simulating `rows` rows of `values_per_row` values.
pub fn simulate_bytes(rows: f64, values_per_row: usize) -> f64 {
    rows * values_per_row as f64 * SIMULATE_BYTES_PER_VALUE
}

/// The most rows of `task_dim` coordinates a fit on `threads` workers can hold in `available` bytes
/// (0 when the workers alone do not fit).
pub fn max_fit_rows(available: f64, task_dim: usize, threads: usize) -> usize {
    let room = (available - fixed_fit_bytes(threads)).max(0.0);
    ((room / (FIT_MATRIX_COPIES * F64)).sqrt() / task_dim.max(1) as f64).floor() as usize
}

/// Bytes this process may still allocate: the least of what is left under the address-space limit
/// (`ulimit -v`: the limit less the address space already mapped), under the cgroup's memory limit
/// (less its usage) and of the machine's available memory; `None` where none is known.
pub fn available_bytes() -> Option<f64> {
    [address_space_left(), cgroup_left(), meminfo_available()].into_iter().flatten().reduce(f64::min)
}

/// Whether this process runs under an address-space limit (`ulimit -v`).
pub fn address_space_limited() -> bool {
    let mut limit = libc::rlimit { rlim_cur: 0, rlim_max: 0 };
    // SAFETY: getrlimit writes one rlimit into the struct we own.
    let ok = unsafe { libc::getrlimit(libc::RLIMIT_AS, &mut limit) } == 0;
    ok && limit.rlim_cur != libc::RLIM_INFINITY
}

fn address_space_left() -> Option<f64> {
    let mut limit = libc::rlimit { rlim_cur: 0, rlim_max: 0 };
    // SAFETY: getrlimit writes one rlimit into the struct we own.
    let ok = unsafe { libc::getrlimit(libc::RLIMIT_AS, &mut limit) } == 0;
    (ok && limit.rlim_cur != libc::RLIM_INFINITY).then(|| (limit.rlim_cur as f64 - mapped_bytes()).max(0.0))
}

/// The address space this process has mapped (VmSize): the binary, its libraries, the heap, the
/// threads' stacks.
fn mapped_bytes() -> f64 {
    let status = std::fs::read_to_string("/proc/self/status").unwrap_or_default();
    let kib = status.lines().find(|l| l.starts_with("VmSize:")).and_then(|l| l.split_whitespace().nth(1)?.parse::<f64>().ok());
    kib.map_or(0.0, |k| k * 1024.0)
}

fn cgroup_left() -> Option<f64> {
    // cgroup v2 ("max" means none), then v1 (a huge number means none).
    let number = |path: &str| std::fs::read_to_string(path).ok().and_then(|t| t.trim().parse::<f64>().ok());
    let v2 = number("/sys/fs/cgroup/memory.max").map(|max| max - number("/sys/fs/cgroup/memory.current").unwrap_or(0.0));
    let v1 = number("/sys/fs/cgroup/memory/memory.limit_in_bytes")
        .filter(|v| *v < 1e18)
        .map(|max| max - number("/sys/fs/cgroup/memory/memory.usage_in_bytes").unwrap_or(0.0));
    v2.or(v1).filter(|v| *v < 1e18).map(|v| v.max(0.0))
}

fn meminfo_available() -> Option<f64> {
    let text = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = text.lines().find(|l| l.starts_with("MemAvailable:"))?;
    let kib: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib * 1024.0)
}

/// Bytes as a short figure ("51.2 GB", "144 MB", "1.3e9 GB").
pub fn gigabytes(bytes: f64) -> String {
    if bytes >= 1e15 {
        format!("{:.1e} GB", bytes / 1e9)
    } else if bytes < 1e9 {
        format!("{:.0} MB", bytes / 1e6)
    } else {
        format!("{:.1} GB", bytes / 1e9)
    }
}

/// The worker threads a fit of `rows` × `task_dim` runs on within `available` bytes: the command's
/// ([`crate::workers::worker_threads`]) when they fit, else one (the results are the same). A fit
/// that does not fit even on one is refused, naming the need and its parts, what is available, how
/// many rows would fit and `remedy` (the caller's flag that lowers it), or, when one worker alone
/// does not fit, the memory limit to raise.
pub fn check_fit(rows: usize, task_dim: usize, available: Option<f64>, remedy: &str) -> Result<usize, MemoryError> {
    let most = crate::workers::worker_threads();
    let Some(available) = available else { return Ok(most) };
    if let Some(threads) = [most, 1].into_iter().find(|&t| fit_bytes(rows, task_dim, t) <= available) {
        return Ok(threads);
    }
    let parts = format!(
        "{FIT_MATRIX_COPIES} matrices of ({rows}·{task_dim})² values, {} and the allocator's {}",
        workers_text(1),
        gigabytes(ALLOCATOR_PAD)
    );
    let fits = max_fit_rows(available, task_dim, 1);
    let what_fits = if fits >= 3 {
        format!("at most {fits} rows fit: {remedy}")
    } else {
        format!("the worker thread alone needs {}: raise the memory limit", gigabytes(fixed_fit_bytes(1)))
    };
    Err(MemoryError(format!(
        "fitting {rows} measurements of {task_dim} coordinates needs about {} ({parts}), more than the {} this process may use; {what_fits}",
        gigabytes(fit_bytes(rows, task_dim, 1)),
        gigabytes(available)
    )))
}

/// The worker threads a fit whose size is checked later (the expansion, [`room_for`]; the kernel
/// form against [`kernel_form_budget`]) runs on within `available` bytes: as [`check_fit`] for no
/// matrices. Refused when one worker alone does not fit, naming the memory limit to raise.
pub fn check_workers(available: Option<f64>) -> Result<usize, MemoryError> {
    let most = crate::workers::worker_threads();
    let Some(available) = available else { return Ok(most) };
    if let Some(threads) = [most, 1].into_iter().find(|&t| fixed_fit_bytes(t) <= available) {
        return Ok(threads);
    }
    Err(MemoryError(format!(
        "a fit needs about {} before its matrices ({} and the allocator's {}), more than the {} this process may use: raise the memory limit",
        gigabytes(fixed_fit_bytes(1)),
        workers_text(1),
        gigabytes(ALLOCATOR_PAD),
        gigabytes(available)
    )))
}

/// [`check_workers`] against what this process may use; the error names the file.
pub fn check_workers_of(file: &std::path::Path) -> crate::Result<usize> {
    check_workers(available_bytes()).context(file.display())
}

/// Bytes the kernel form's (N·m)² matrices may take on `threads` workers: what this process may
/// use less the workers' and the allocator's ([`fixed_fit_bytes`]); `None` where nothing is known.
pub fn kernel_form_budget(threads: usize) -> Option<f64> {
    available_bytes().map(|a| (a - fixed_fit_bytes(threads)).max(0.0))
}

/// "1 worker thread of 0.08 GB (faer's matrix-multiply workspace 0.07 GB and an 8 MiB stack)".
fn workers_text(threads: usize) -> String {
    format!(
        "{threads} worker thread(s) of {} each (faer's matrix-multiply workspace {} and an {} MiB stack)",
        gigabytes(worker_bytes(threads)),
        gigabytes(gemm_workspace_bytes()),
        crate::workers::WORKER_STACK_BYTES >> 20
    )
}

/// [`check_fit`] for all rows of `data`, read from `file`, against what this process may use; the
/// error names the file. Returns the worker threads to fit on (`crate::workers::on_workers`).
pub fn check_fit_of(file: &std::path::Path, data: &crate::data::Measurements, remedy: &str) -> crate::Result<usize> {
    check_fit(data.len(), data.task_dim, available_bytes(), remedy).context(file.display())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Issue 17 item 5: nothing checked the size up front; 20k rows under a 6 GB limit panicked
    /// inside faer (exit 101).
    #[test]
    fn memory_needed_is_estimated_before_allocating() {
        let e = check_fit(20_000, 3, Some(6e9), "--max-rows").unwrap_err().to_string();
        assert!(e.contains("needs about 115.") && e.contains("6.0 GB") && e.contains("--max-rows"), "{e}");
        let k = max_fit_rows(6e9, 3, 1);
        assert!(check_fit(k, 3, Some(6e9), "").is_ok() && check_fit(k + 1, 3, Some(6e9), "").is_err(), "{k}");
        assert!(check_fit(4096, 2, Some(6e9), "").is_ok());
        assert!(check_fit(1_000_000, 3, None, "").is_ok());
        // What this process may use is known on Linux and positive.
        assert!(available_bytes().is_some_and(|b| b > 0.0));
    }

    /// Issue 27 item 2: a memory limit below faer's matrix-multiply workspace (a thread-local buffer
    /// of twice the L3 figure, about 1 GB on a large server) aborted a 256-row fit, since the
    /// estimate counted the N² matrices only. It now counts each worker's workspace and stack, and a
    /// fit that fits on one worker but not on two runs on one.
    #[test]
    fn the_estimate_counts_each_workers_workspace() {
        let one = fixed_fit_bytes(1);
        assert!(one >= gemm_workspace_bytes() + 8.0 * 1048576.0 + ALLOCATOR_PAD);
        assert!(fixed_fit_bytes(2) >= 2.0 * (2.0 * gemm_workspace_bytes() + 8.0 * 1048576.0) + ALLOCATOR_PAD);
        assert!(gemm_workspace_bytes() >= 2.0 * 2.0 * 1048576.0, "at least two blocks of 2 MiB");
        let e = check_fit(256, 2, Some(0.9 * one), "--max-rows N").unwrap_err().to_string();
        assert!(
            e.contains("faer's matrix-multiply workspace")
                && e.contains("the worker thread alone needs")
                && e.contains("raise the memory limit"),
            "{e}"
        );
        assert_eq!(check_fit(256, 2, Some(one + matrix_bytes(256, 2)), ""), Ok(1));
        let most = crate::workers::worker_threads();
        assert_eq!(check_fit(256, 2, Some(fixed_fit_bytes(most) + matrix_bytes(256, 2)), ""), Ok(most));
        let e = check_fit(2048, 2, Some(one + matrix_bytes(1024, 2)), "--max-rows N").unwrap_err().to_string();
        assert!(e.contains("at most 1024 rows fit: --max-rows N"), "{e}");
    }

    /// Issue 27 item 2: the expansion's fits check their workers up front too.
    #[test]
    fn the_workers_alone_are_checked() {
        let one = fixed_fit_bytes(1);
        assert_eq!(check_workers(Some(one)), Ok(1));
        assert_eq!(check_workers(None), Ok(crate::workers::worker_threads()));
        let e = check_workers(Some(0.5 * one)).unwrap_err().to_string();
        assert!(e.contains("faer's matrix-multiply workspace") && e.contains("raise the memory limit"), "{e}");
    }

    #[test]
    fn sysfs_cache_figures_parse() {
        assert_eq!(cache_size("32768K"), Some(32 << 20));
        assert_eq!((cache_size("2M"), cache_size("1G"), cache_size("512")), (Some(2 << 20), Some(1 << 30), Some(512)));
        assert_eq!((cpu_count("0-3,8"), cpu_count("5"), cpu_count("x")), (Some(5), Some(1), None));
    }
}

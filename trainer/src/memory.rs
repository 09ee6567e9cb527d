//! Memory a command will need, estimated before it allocates, against what the process may use, and
//! the worker threads it computes on (the threads that estimate counts):
//! a fit or simulation too large for the machine is refused up front with the figure and the flag
//! that lowers it (exit 1), instead of an allocation failure deep inside faer (exit 101) or an abort
//! (exit 134). The estimate counts every large allocation: the (N·m)² matrices, and per worker
//! thread faer's matrix-multiply buffers and the thread's stack.
//!
//! What it reads off the machine — the cache figures that size faer's multiply buffers
//! ([`CacheSizes`]), the worker threads and what this process may still allocate — are inputs of
//! the pure functions here ([`Host`]), so the tests run them as a laptop, a server reporting a
//! 480 MiB L3, one core or 64, with and without a limit.

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

/// What the memory check reads off the machine: the caches (faer's multiply buffers follow them),
/// the worker threads a command computes on, and the bytes this process may still allocate (`None`
/// where nothing is known).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Host {
    pub caches: CacheSizes,
    pub workers: usize,
    pub available: Option<f64>,
}

impl Host {
    /// This machine and process now.
    pub fn this_process() -> Host {
        Host::with_available(available_bytes())
    }

    /// This machine's caches and workers, with `available` bytes.
    pub fn with_available(available: Option<f64>) -> Host {
        Host { caches: CacheSizes::of_this_host(), workers: worker_threads(), available }
    }
}

/// The cache figures faer's matrix multiply (gemm 0.19) sizes its buffers by, as gemm reads them
/// from Linux's sysfs: L1 and L2 per CPU sharing them, L3 whole (bytes), with L1's line and
/// associativity and L3's associativity.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CacheSizes {
    pub l1: usize,
    pub l1_line: usize,
    pub l1_ways: usize,
    pub l2: usize,
    pub l3: usize,
    pub l3_ways: usize,
}

impl CacheSizes {
    /// gemm's figures where sysfs says nothing (x86-64).
    pub const DEFAULT: CacheSizes = CacheSizes { l1: 32 << 10, l1_line: 64, l1_ways: 8, l2: 256 << 10, l3: 2 << 20, l3_ways: 8 };

    /// This machine's, read once (gemm reads them once too).
    pub fn of_this_host() -> CacheSizes {
        static SIZES: std::sync::OnceLock<CacheSizes> = std::sync::OnceLock::new();
        *SIZES.get_or_init(|| CacheSizes::from_sysfs(std::path::Path::new("/sys/devices/system/cpu")).unwrap_or(CacheSizes::DEFAULT))
    }

    /// The figures under a sysfs CPU folder (`/sys/devices/system/cpu` or a copy), as gemm reads
    /// them: each data or unified cache of each CPU, L1 and L2 divided by the CPUs sharing them, a
    /// level it finds nothing for at gemm's default. `None` when the folder cannot be read.
    pub fn from_sysfs(cpu_root: &std::path::Path) -> Option<CacheSizes> {
        let mut found: [Option<(usize, usize, usize)>; 3] = [None; 3]; // (bytes, line, ways)
        for cpu in std::fs::read_dir(cpu_root).ok()?.flatten() {
            if !cpu.file_name().to_string_lossy().starts_with("cpu") || !cpu.path().join("cache").is_dir() {
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
                let (Some(level), Some(size)) =
                    (read("level").and_then(|l| l.parse::<usize>().ok()), read("size").and_then(|s| cache_size(&s)))
                else {
                    continue;
                };
                if !(1..=3).contains(&level) {
                    continue;
                }
                let shared = if level == 3 { 1 } else { read("shared_cpu_list").and_then(|l| cpu_count(&l)).unwrap_or(1).max(1) };
                let line = read("coherency_line_size").and_then(|v| v.parse().ok()).unwrap_or(64);
                let ways = read("ways_of_associativity").and_then(|v| v.parse().ok()).unwrap_or(8);
                if found[level - 1].is_none_or(|(_, l, _)| line >= l) {
                    found[level - 1] = Some((size / shared, line, ways));
                }
            }
        }
        let d = CacheSizes::DEFAULT;
        let [l1, l2, l3] = found;
        let l1 = l1.filter(|c| c.0 > 0).unwrap_or((d.l1, d.l1_line, d.l1_ways));
        let l2 = l2.filter(|c| c.0 > 0).map_or(d.l2, |c| c.0);
        let l3 = l3.filter(|c| c.0 > 0).unwrap_or((d.l3, 64, d.l3_ways));
        Some(CacheSizes { l1: l1.0, l1_line: l1.1, l1_ways: l1.2, l2, l3: l3.0, l3_ways: l3.2 })
    }

    /// The largest depth block (kc, values) gemm's blocking picks for f64 with any of its x86
    /// register blocks (`gemm_common::cache::kernel_params`: A's micro-panels in distinct L1 sets,
    /// A's and B's in L1's ways, at least 512).
    fn depth_block(&self) -> usize {
        let sets_bytes = self.l1_line.max(64) * (self.l1.max(32 << 10) / (self.l1_line.max(64) * self.l1_ways.max(2))).max(1);
        GEMM_F64_BLOCKS
            .iter()
            .map(|&(mr, nr)| {
                let gcd = gcd(mr * 8, sets_bytes);
                let kc_0 = sets_bytes / gcd;
                let (c_lhs, c_rhs) = ((mr * 8) / gcd, (nr * kc_0 * 8) / sets_bytes);
                let multiplier = (self.l1_ways.max(2) / (c_lhs + c_rhs).max(1)).max(1);
                (kc_0 * multiplier.next_power_of_two()).max(512)
            })
            .max()
            .unwrap_or(512)
    }

    /// The most columns (nc) of a packed right-hand side block with depth `kc`: what L3 holds
    /// with one way left for the left-hand side, plus the rounding to a register block.
    fn column_block(&self, kc: usize) -> usize {
        let ways = self.l3_ways.max(2);
        (ways - 1) * self.l3 / ways / (8 * kc.max(1)) + GEMM_MAX_NR
    }
}

/// gemm 0.19's f64 register blocks (rows MR, columns NR) on x86-64: scalar, AVX2/FMA, AVX-512.
const GEMM_F64_BLOCKS: [(usize, usize); 3] = [(1, 4), (8, 6), (32, 6)];
/// The largest MR and NR among them (a packed block is rounded up to these).
const GEMM_MAX_MR: usize = 32;
const GEMM_MAX_NR: usize = 6;

fn gcd(a: usize, b: usize) -> usize {
    if b == 0 {
        a.max(1)
    } else {
        gcd(b, a % b)
    }
}

/// faer's matrix-multiply buffers on one thread, for matrices of at most `dim` rows and columns
/// (faer 0.24 without `std` multiplies through gemm 0.19, see the workspace's Cargo.toml): the
/// thread-local block of its L2 figure, and per multiply a packed copy of the right-hand side's
/// block (depth kc × nc columns, each at most the matrix's own) and of a short left-hand side (kc ×
/// at most 2 row blocks of 8 MR). Both follow the problem: a 16-row fit's multiply packs kilobytes
/// on any host; the L3 figure only caps nc. `tests/gemm_workspace.rs` checks this against the
/// allocations.
pub fn gemm_workspace_bytes_for(caches: &CacheSizes, dim: usize) -> f64 {
    let kc = caches.depth_block().min(dim.max(1));
    let nc = dim.next_multiple_of(GEMM_MAX_NR).min(caches.column_block(kc));
    let lhs = dim.next_multiple_of(GEMM_MAX_MR).min(16 * GEMM_MAX_MR);
    // The aligned allocations' padding (cache lines, pages) on each of the three buffers.
    let padding = 3.0 * 4096.0;
    caches.l2 as f64 + F64 * (kc * (nc + lhs)) as f64 + padding
}

/// [`gemm_workspace_bytes_for`] on this machine's caches.
pub fn gemm_workspace_bytes(dim: usize) -> f64 {
    gemm_workspace_bytes_for(&CacheSizes::of_this_host(), dim)
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
/// worker threads of a machine with `caches`: the matrices, and what the threads and the allocator
/// hold ([`fixed_fit_bytes`]).
pub fn fit_bytes(caches: &CacheSizes, rows: usize, task_dim: usize, threads: usize) -> f64 {
    matrix_bytes(rows, task_dim) + fixed_fit_bytes(caches, threads, rows.saturating_mul(task_dim))
}

/// The (N·m)² matrices of a fit of `rows` × `task_dim`.
fn matrix_bytes(rows: usize, task_dim: usize) -> f64 {
    let unknowns = rows as f64 * task_dim as f64;
    FIT_MATRIX_COPIES * unknowns * unknowns * F64
}

/// What a computation on `threads` workers whose matrices have at most `dim` rows and columns
/// holds besides its matrices: each worker's ([`worker_bytes`]) and the allocator's pad.
pub fn fixed_fit_bytes(caches: &CacheSizes, threads: usize, dim: usize) -> f64 {
    threads as f64 * worker_bytes(caches, threads, dim) + ALLOCATOR_PAD
}

/// One of `threads` worker threads multiplying matrices of at most `dim` rows and columns: faer's
/// multiply buffers and the thread's stack. A worker that waits inside a parallel multiply may start
/// another one (rayon's work stealing), with buffers of its own: two per worker when there are
/// several, one on a single worker.
pub fn worker_bytes(caches: &CacheSizes, threads: usize, dim: usize) -> f64 {
    let buffers = if threads > 1 { 2.0 } else { 1.0 };
    buffers * gemm_workspace_bytes_for(caches, dim) + WORKER_STACK_BYTES as f64
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

/// Whether `bytes` more, in matrices of at most `dim` rows and columns, fit in what this process
/// may use now, less the multiply buffers the workers it runs on may allocate meanwhile (two each,
/// [`worker_bytes`]) and a margin for small blocks. The error gives both figures.
pub fn room_for(bytes: f64, dim: usize) -> Result<(), MemoryError> {
    let host = Host { workers: current_workers(), ..Host::this_process() };
    room_for_on(&host, bytes, dim)
}

/// [`room_for`] on a given machine and process.
pub fn room_for_on(host: &Host, bytes: f64, dim: usize) -> Result<(), MemoryError> {
    let pending = pending_buffers(host, dim);
    let room = host.available.map_or(f64::INFINITY, |available| available - pending - SMALL_BLOCKS_MARGIN);
    if host.available.is_none() || bytes <= room {
        // What is in use already (the mapped address space) plus this: the command's need so far.
        record_need(mapped_bytes() + bytes + pending);
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
/// (0 when not even one does).
pub fn max_fit_rows(caches: &CacheSizes, available: f64, task_dim: usize, threads: usize) -> usize {
    let fits = |rows: usize| fit_bytes(caches, rows, task_dim, threads) <= available;
    // The matrices grow as rows², the buffers at most linearly: the bound without buffers is an
    // upper one, and the count is found by bisection below it.
    if !fits(1) {
        return 0;
    }
    let upper = ((available / (FIT_MATRIX_COPIES * F64)).max(0.0).sqrt() / task_dim.max(1) as f64).floor() as usize + 1;
    let (mut lo, mut hi) = (1, upper.max(2));
    while hi - lo > 1 {
        let mid = lo + (hi - lo) / 2;
        if fits(mid) {
            lo = mid
        } else {
            hi = mid
        }
    }
    lo
}

/// Bytes this process may still allocate: the least of what is left under the address-space limit
/// (`ulimit -v`: the limit less the address space already mapped), under the cgroup's memory limit
/// (less its usage) and of the machine's available memory; `None` where none is known.
pub fn available_bytes() -> Option<f64> {
    let cgroups = std::fs::read_to_string("/proc/self/cgroup").unwrap_or_default();
    let cgroup = cgroup_left_at(std::path::Path::new("/sys/fs/cgroup"), &cgroups);
    [address_space_left(), cgroup, meminfo_available()].into_iter().flatten().reduce(f64::min)
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
    status_kib("VmSize:").map_or(0.0, |k| k * 1024.0)
}

/// The most address space this process has mapped so far (VmPeak, bytes): what an address-space
/// limit had to allow.
pub fn peak_mapped_bytes() -> Option<f64> {
    status_kib("VmPeak:").map(|k| k * 1024.0)
}

/// The most memory this process has held resident so far (VmHWM, bytes): what a cgroup limit had
/// to allow.
pub fn peak_resident_bytes() -> Option<f64> {
    status_kib("VmHWM:").map(|k| k * 1024.0)
}

/// A `kB` figure of /proc/self/status.
fn status_kib(field: &str) -> Option<f64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    status.lines().find(|l| l.starts_with(field)).and_then(|l| l.split_whitespace().nth(1)?.parse::<f64>().ok())
}

/// What is left under the tightest memory limit of this process's cgroups and their ancestors, as
/// `/proc/self/cgroup` (`cgroups`) names them below the cgroup mount `root`: cgroup v2's
/// `memory.max` less `memory.current` ("max" means none) along the unified path (`0::/path`), and
/// cgroup v1's `memory/…/memory.limit_in_bytes` less its usage (a huge number means none) along the
/// memory controller's path (`N:memory:/path`). `None` where no limit is set. A limit on a parent
/// (a systemd slice, a container's cgroup) binds as much as one on the process's own.
pub fn cgroup_left_at(root: &std::path::Path, cgroups: &str) -> Option<f64> {
    let number = |path: std::path::PathBuf| std::fs::read_to_string(path).ok().and_then(|t| t.trim().parse::<f64>().ok());
    // The tightest of (limit − usage) from `dir` up to `top`.
    let tightest = |top: std::path::PathBuf, own: &str, limit: &str, usage: &str| -> Option<f64> {
        let mut left: Option<f64> = None;
        let mut dir = top.join(own.trim_start_matches('/'));
        while dir.starts_with(&top) {
            if let Some(max) = number(dir.join(limit)).filter(|v| *v < 1e18) {
                let here = (max - number(dir.join(usage)).unwrap_or(0.0)).max(0.0);
                left = Some(left.map_or(here, |l| l.min(here)));
            }
            if dir == top || !dir.pop() {
                break;
            }
        }
        left
    };
    let mut left: Option<f64> = None;
    for line in cgroups.lines() {
        let mut fields = line.splitn(3, ':');
        let (Some(_), Some(controllers), Some(path)) = (fields.next(), fields.next(), fields.next()) else { continue };
        let here = if controllers.is_empty() {
            tightest(root.to_path_buf(), path, "memory.max", "memory.current")
        } else if controllers.split(',').any(|c| c == "memory") {
            tightest(root.join("memory"), path, "memory.limit_in_bytes", "memory.usage_in_bytes")
        } else {
            None
        };
        if let Some(h) = here {
            left = Some(left.map_or(h, |l: f64| l.min(h)));
        }
    }
    left
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
/// ([`worker_threads`]) when they fit, else one (the results are the same). A fit
/// that does not fit even on one is refused, naming the need and its parts, what is available, how
/// many rows would fit and `remedy` (the caller's flag that lowers it), or, when one worker alone
/// does not fit, the memory limit to raise.
pub fn check_fit(rows: usize, task_dim: usize, available: Option<f64>, remedy: &str) -> Result<usize, MemoryError> {
    check_fit_on(&Host::with_available(available), rows, task_dim, remedy)
}

/// The largest need a check of this process let through (bytes), what `cbd fit` reports beside the
/// peak it measured ([`needed_so_far`]).
static LARGEST_NEED: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);

fn record_need(bytes: f64) {
    LARGEST_NEED.fetch_max(bytes.max(0.0) as u64, std::sync::atomic::Ordering::Relaxed);
}

/// The largest memory need this process's checks estimated (and let through) so far: the fixed
/// part with the workers, or that with a later allocation ([`room_for`]); 0 before any check.
pub fn needed_so_far() -> f64 {
    LARGEST_NEED.load(std::sync::atomic::Ordering::Relaxed) as f64
}

/// Records that `bytes` more in matrices of at most `dim` rows and columns are about to be allocated
/// where the up-front check already covered them (the kernel form within its budget): the need
/// [`needed_so_far`] reports, counted as [`room_for`] counts it.
pub fn note_need(bytes: f64, dim: usize) {
    let host = Host { workers: current_workers(), ..Host::with_available(None) };
    record_need(mapped_bytes() + bytes + pending_buffers(&host, dim));
}

/// The multiply buffers `host`'s workers may allocate while matrices of at most `dim` rows and
/// columns are computed: two each ([`worker_bytes`]).
fn pending_buffers(host: &Host, dim: usize) -> f64 {
    2.0 * host.workers.max(1) as f64 * gemm_workspace_bytes_for(&host.caches, dim)
}

/// The workers to run on: `host.workers` when `need(workers)` fits what is available, else one
/// when `need(1)` does, the need let through recorded ([`needed_so_far`]); `Err(available)` when
/// not even one worker fits.
fn workers_within(host: &Host, need: impl Fn(usize) -> f64) -> Result<usize, f64> {
    let most = host.workers.max(1);
    let threads = match host.available {
        None => most,
        Some(available) => [most, 1].into_iter().find(|&t| need(t) <= available).ok_or(available)?,
    };
    record_need(need(threads));
    Ok(threads)
}

/// [`check_fit`] on a given machine and process.
pub fn check_fit_on(host: &Host, rows: usize, task_dim: usize, remedy: &str) -> Result<usize, MemoryError> {
    let caches = &host.caches;
    let available = match workers_within(host, |t| fit_bytes(caches, rows, task_dim, t)) {
        Ok(threads) => return Ok(threads),
        Err(available) => available,
    };
    let dim = rows.saturating_mul(task_dim);
    let parts = format!(
        "{FIT_MATRIX_COPIES} matrices of ({rows}·{task_dim})² values, {} and the allocator's {}",
        workers_text(caches, 1, dim),
        gigabytes(ALLOCATOR_PAD)
    );
    let fits = max_fit_rows(caches, available, task_dim, 1);
    let what_fits = if fits >= 3 {
        format!("at most {fits} rows fit: {remedy}")
    } else {
        format!("the worker thread alone needs {}: raise the memory limit", gigabytes(fixed_fit_bytes(caches, 1, 3 * task_dim)))
    };
    Err(MemoryError(format!(
        "fitting {rows} measurements of {task_dim} coordinates needs about {} ({parts}), more than the {} this process may use; {what_fits}",
        gigabytes(fit_bytes(caches, rows, task_dim, 1)),
        gigabytes(available)
    )))
}

/// The worker threads a computation whose matrices are checked later (the expansion, [`room_for`];
/// the kernel form against [`kernel_form_budget`]) runs on within `available` bytes, its matrices
/// at most `dim` rows and columns: as [`check_fit`] for no matrices. Refused when one worker alone
/// does not fit: naming `remedy` (the caller's flag that lowers the size) when the multiply buffers
/// of so large a problem are what does not fit, else the memory limit to raise.
pub fn check_workers(available: Option<f64>, dim: usize, remedy: &str) -> Result<usize, MemoryError> {
    check_workers_on(&Host::with_available(available), dim, remedy)
}

/// [`check_workers`] on a given machine and process.
pub fn check_workers_on(host: &Host, dim: usize, remedy: &str) -> Result<usize, MemoryError> {
    let caches = &host.caches;
    let available = match workers_within(host, |t| fixed_fit_bytes(caches, t, dim)) {
        Ok(threads) => return Ok(threads),
        Err(available) => available,
    };
    // A small problem's worker fits: this one's size is what does not.
    let what = match fixed_fit_bytes(caches, 1, SMALL_DIM) <= available {
        true => remedy,
        false => "raise the memory limit",
    };
    Err(MemoryError(format!(
        "a fit needs about {} before its matrices ({} and the allocator's {}), more than the {} this process may use: {what}",
        gigabytes(fixed_fit_bytes(caches, 1, dim)),
        workers_text(caches, 1, dim),
        gigabytes(ALLOCATOR_PAD),
        gigabytes(available)
    )))
}

/// [`check_workers`] against what this process may use; the error names the file.
pub fn check_workers_of(file: &std::path::Path, dim: usize, remedy: &str) -> crate::Result<usize> {
    check_workers(available_bytes(), dim, remedy).context(file.display())
}

/// Bytes the kernel form's (N·m)² matrices may take on `threads` workers: what this process may
/// use less the workers' and the allocator's ([`fixed_fit_bytes`]) for matrices of `dim` rows;
/// `None` where nothing is known.
pub fn kernel_form_budget(threads: usize, dim: usize) -> Option<f64> {
    available_bytes().map(|a| (a - fixed_fit_bytes(&CacheSizes::of_this_host(), threads, dim)).max(0.0))
}

/// "1 worker thread(s) of 0.02 GB each (faer's matrix-multiply buffers 0.00 GB and an 8 MiB stack)".
fn workers_text(caches: &CacheSizes, threads: usize, dim: usize) -> String {
    format!(
        "{threads} worker thread(s) of {} each (faer's matrix-multiply buffers {} and an {} MiB stack)",
        gigabytes(worker_bytes(caches, threads, dim)),
        gigabytes(gemm_workspace_bytes_for(caches, dim)),
        WORKER_STACK_BYTES >> 20
    )
}

/// [`check_fit`] for `rows` rows of `task_dim` coordinates, read from `file`, against what this
/// process may use; the error names the file. Returns the worker threads to fit on
/// (`on_workers`). Sizes only: the memory's estimates need no rows.
pub fn check_fit_of(file: &std::path::Path, rows: usize, task_dim: usize, remedy: &str) -> crate::Result<usize> {
    check_fit(rows, task_dim, available_bytes(), remedy).context(file.display())
}

/// The number of workers for a command: [`MAX_WORKERS`] on a machine with the
/// cores, one when the memory this process may use does not hold a second worker's buffers and
/// stack with room to spare (half of it for the computation). Sized for small problems (the
/// command's own checks then size its fits).
pub fn workers_for_memory(available: Option<f64>) -> usize {
    workers_for_memory_on(&Host::with_available(available), default_workers())
}

/// [`workers_for_memory`] on a given machine, for `most` workers at most.
pub fn workers_for_memory_on(host: &Host, most: usize) -> usize {
    let most = most.max(1);
    match host.available {
        Some(bytes) if bytes < 2.0 * most as f64 * worker_bytes(&host.caches, most, SMALL_DIM) => 1,
        _ => most,
    }
}

/// Matrix dimension the command-wide worker count is sized for: a 256-row fit of 3 coordinates.
const SMALL_DIM: usize = 768;

// The worker threads a `cbd` command computes on: one rayon pool, built before the command runs
// and sized here, so that every parallel piece of faer and of the flow runs on threads the memory
// check counts. Without it faer's `Par::Rayon` reached rayon's global pool, which has a thread per
// core (each holding faer's matrix-multiply buffers, `gemm_workspace_bytes`)
// and panics ("the global thread pool has not been initialized") when its threads cannot start.

/// Most worker threads: faer's factorisations are split into a fixed two pieces
/// (`numeric::FIXED_SPLIT`), so a third thread would add a workspace and no speed.
pub const MAX_WORKERS: usize = 2;

/// Stack of each worker: the main thread's 8 MiB, since the command runs on a worker.
pub const WORKER_STACK_BYTES: usize = 8 << 20;

/// The pool's size once [`run_in_pool`] has built it.
static WORKERS: std::sync::OnceLock<usize> = std::sync::OnceLock::new();

/// Threads this process computes on: the pool's size, or before there is one the number it would
/// have, min(cores, [`MAX_WORKERS`]).
pub fn worker_threads() -> usize {
    WORKERS.get().copied().unwrap_or_else(default_workers)
}

/// The workers of the pool this runs on (a fit's), else [`worker_threads`].
pub fn current_workers() -> usize {
    match rayon::current_thread_index() {
        Some(_) => rayon::current_num_threads(),
        None => worker_threads(),
    }
}

/// The workers a command starts on this machine ([`workers_for_cores`] of its cores).
pub fn default_workers() -> usize {
    workers_for_cores(std::thread::available_parallelism().map_or(1, |n| n.get()))
}

/// The workers a command starts on a machine with `cores` cores: one per core, at most [`MAX_WORKERS`].
pub fn workers_for_cores(cores: usize) -> usize {
    cores.clamp(1, MAX_WORKERS)
}

/// Runs `f` on a new pool of `threads` workers (the results do not depend on the count: the work is
/// split into fixed pieces). A pool whose threads cannot start (a memory limit too low for their
/// stacks) is an error, never a panic.
pub fn run_in_pool<R: Send>(threads: usize, f: impl FnOnce() -> R + Send) -> Result<R, PoolError> {
    let threads = threads.clamp(1, MAX_WORKERS);
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .stack_size(WORKER_STACK_BYTES)
        .thread_name(|k| format!("cbd-worker-{k}"))
        .build()
        .map_err(|source| PoolError { threads, source })?;
    let _ = WORKERS.set(threads);
    Ok(pool.install(f))
}

/// The worker pool's threads could not start ([`run_in_pool`]).
#[derive(Debug, thiserror::Error)]
#[error("cannot start {threads} worker thread(s) of {} MiB stack: {source} (is the memory limit too low?)", WORKER_STACK_BYTES >> 20)]
pub struct PoolError {
    pub threads: usize,
    #[source]
    pub source: rayon::ThreadPoolBuildError,
}

impl From<PoolError> for crate::Error {
    fn from(e: PoolError) -> crate::Error {
        crate::Error::stage("workers", e)
    }
}

/// Runs `f` on `threads` workers: on the pool it is called from when that has no more (a fit inside
/// `cbd fit` runs on the command's pool: a pool per fit would start threads, each with its own
/// workspace, that the memory check does not count), else on a new pool of `threads` (one worker
/// when the memory check found room for one only; the command's idle workers hold no workspace).
pub fn on_workers<R: Send>(threads: usize, f: impl FnOnce() -> R + Send) -> R {
    let threads = threads.max(1);
    if rayon::current_thread_index().is_some() && rayon::current_num_threads() <= threads {
        return f();
    }
    match rayon::ThreadPoolBuilder::new().num_threads(threads).stack_size(WORKER_STACK_BYTES).build() {
        Ok(pool) => pool.install(f),
        Err(_) => f(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A laptop: 32 KiB 8-way L1 and 512 KiB L2 per core, an 8 MiB L3.
    const LAPTOP: CacheSizes = CacheSizes { l1: 32 << 10, l1_line: 64, l1_ways: 8, l2: 512 << 10, l3: 8 << 20, l3_ways: 16 };
    /// A cloud server VM reporting its host's 480 MiB L3 (issue 48), 48 KiB 12-way L1, 2 MiB L2.
    const SERVER: CacheSizes = CacheSizes { l1: 48 << 10, l1_line: 64, l1_ways: 12, l2: 2 << 20, l3: 480 << 20, l3_ways: 16 };

    fn host(caches: CacheSizes, workers: usize, available: Option<f64>) -> Host {
        Host { caches, workers, available }
    }

    /// Issue 17 item 5: nothing checked the size up front; 20k rows under a 6 GB limit panicked
    /// inside faer (exit 101). The figure is the matrices' on every host (issue 48: it was pinned
    /// to one machine's L3).
    #[test]
    fn memory_needed_is_estimated_before_allocating() {
        for caches in [LAPTOP, SERVER, CacheSizes::DEFAULT] {
            for workers in [1, 2] {
                let h = host(caches, workers, Some(6e9));
                let e = check_fit_on(&h, 20_000, 3, "--max-rows").unwrap_err().to_string();
                assert!(e.contains("needs about 115.") && e.contains("6.0 GB") && e.contains("--max-rows"), "{e}");
                let k = max_fit_rows(&caches, 6e9, 3, 1);
                assert!(check_fit_on(&h, k, 3, "").is_ok() && check_fit_on(&h, k + 1, 3, "").is_err(), "{k}");
                assert!(check_fit_on(&h, 4096, 2, "").is_ok());
                assert!(check_fit_on(&host(caches, workers, None), 1_000_000, 3, "").is_ok());
            }
        }
        // What this process may use is known on Linux and positive.
        assert!(available_bytes().is_some_and(|b| b > 0.0));
    }

    /// Issue 48: on a server reporting a 480 MiB L3 a 16-row diagnose needed 1.1 GB and a 256-row
    /// fit was refused under 512 MB. The multiply's buffers now follow the problem.
    #[test]
    fn small_fits_fit_small_limits_on_any_host() {
        for caches in [LAPTOP, SERVER, CacheSizes::DEFAULT] {
            let ws = gemm_workspace_bytes_for(&caches, 32);
            assert!(ws < caches.l2 as f64 + 1e6, "a 16-row fit's multiply buffers: {ws}");
            for workers in [1, 2] {
                assert_eq!(check_fit_on(&host(caches, workers, Some(386e6)), 16, 2, "").map(|_| ()), Ok(()));
                assert_eq!(check_fit_on(&host(caches, workers, Some(512e6)), 256, 3, "").map(|_| ()), Ok(()));
                assert_eq!(check_workers_on(&host(caches, workers, Some(256e6)), 768, ""), Ok(workers));
            }
        }
    }

    /// The buffers grow with the problem, never past the cap the caches set, and the fit's
    /// estimate is dominated by its matrices at every size where they matter.
    #[test]
    fn multiply_buffers_follow_the_problem() {
        for caches in [LAPTOP, SERVER] {
            let sizes = [16, 512, 8192, 32768, 1 << 20];
            let ws: Vec<f64> = sizes.iter().map(|&d| gemm_workspace_bytes_for(&caches, d)).collect();
            assert!(ws.windows(2).all(|w| w[0] <= w[1]), "{ws:?}");
            // At most a depth block by the L3 figure's column block and the left-hand block.
            let kc = caches.depth_block();
            let cap = caches.l2 as f64 + 8.0 * (kc * (caches.column_block(kc) + 16 * GEMM_MAX_MR)) as f64 + 3.0 * 4096.0;
            assert_eq!(ws[4], cap);
            // N = 4096, m = 2: a worker's buffers (two multiplies' packed blocks at kc = 512 or 1024)
            // are under 10 % of the fit's matrices.
            assert!(worker_bytes(&caches, 2, 8192) < 0.1 * matrix_bytes(4096, 2), "{}", worker_bytes(&caches, 2, 8192));
        }
        // The laptop's L3 caps its column block below the server's.
        assert!(gemm_workspace_bytes_for(&LAPTOP, 1 << 20) < gemm_workspace_bytes_for(&SERVER, 1 << 20));
        // gemm's depth block on a 32 KiB 8-way L1 is 512 values; a 48 KiB 12-way L1 allows 1024 (AVX2).
        assert_eq!((LAPTOP.depth_block(), SERVER.depth_block()), (512, 1024));
    }

    /// Issue 27 item 2: a memory limit below the workers' buffers and stacks aborted a 256-row fit;
    /// the estimate counts each worker's, and a fit that fits on one worker but not on two runs on one.
    #[test]
    fn the_estimate_counts_each_workers_workspace() {
        for caches in [LAPTOP, SERVER] {
            let dim = 512;
            let one = fixed_fit_bytes(&caches, 1, dim);
            assert!(one >= gemm_workspace_bytes_for(&caches, dim) + 8.0 * 1048576.0 + ALLOCATOR_PAD);
            assert!(
                fixed_fit_bytes(&caches, 2, dim) >= 2.0 * (2.0 * gemm_workspace_bytes_for(&caches, dim) + 8.0 * 1048576.0) + ALLOCATOR_PAD
            );
            let e = check_fit_on(&host(caches, 2, Some(0.9 * one)), 256, 2, "--max-rows N").unwrap_err().to_string();
            assert!(
                e.contains("faer's matrix-multiply buffers")
                    && e.contains("the worker thread alone needs")
                    && e.contains("raise the memory limit"),
                "{e}"
            );
            for most in [1, 2] {
                let h = host(caches, most, Some(one + matrix_bytes(256, 2)));
                assert_eq!(check_fit_on(&h, 256, 2, ""), Ok(1));
                let h = host(caches, most, Some(fixed_fit_bytes(&caches, most, dim) + matrix_bytes(256, 2)));
                assert_eq!(check_fit_on(&h, 256, 2, ""), Ok(most));
            }
            let h = host(caches, 2, Some(fixed_fit_bytes(&caches, 1, 2048) + matrix_bytes(1024, 2)));
            let e = check_fit_on(&h, 2048, 2, "--max-rows N").unwrap_err().to_string();
            assert!(e.contains("at most 102") && e.contains("rows fit: --max-rows N"), "{e}");
        }
    }

    /// Issue 27 item 2: the expansion's fits check their workers up front too.
    #[test]
    fn the_workers_alone_are_checked() {
        for caches in [LAPTOP, SERVER] {
            let one = fixed_fit_bytes(&caches, 1, 4096);
            assert_eq!(check_workers_on(&host(caches, 2, Some(one)), 4096, "lower --grid"), Ok(1));
            assert_eq!(check_workers_on(&host(caches, 2, None), 4096, "lower --grid"), Ok(2));
            let e = check_workers_on(&host(caches, 2, Some(0.5 * fixed_fit_bytes(&caches, 1, 16))), 4096, "lower --grid")
                .unwrap_err()
                .to_string();
            assert!(e.contains("faer's matrix-multiply buffers") && e.contains("raise the memory limit"), "{e}");
            // Issue 48: `demo --grid 3000` on a 480 MiB-L3 host was told to raise the limit; a problem
            // whose own buffers do not fit, where a small one's would, names the flag.
            let huge = 18_000_000;
            let small = fixed_fit_bytes(&caches, 1, SMALL_DIM);
            if fixed_fit_bytes(&caches, 1, huge) > 1.5 * small {
                let e = check_workers_on(&host(caches, 2, Some(1.5 * small)), huge, "lower --grid").unwrap_err().to_string();
                assert!(e.contains("lower --grid") && !e.contains("raise the memory limit"), "{e}");
            }
        }
    }

    /// One core or 64: the command's workers are at most `MAX_WORKERS`, one when a second does
    /// not fit twice over.
    #[test]
    fn workers_follow_cores_and_memory() {
        assert_eq!((workers_for_cores(1), workers_for_cores(64)), (1, MAX_WORKERS));
        for caches in [LAPTOP, SERVER] {
            for cores in [1, 64] {
                let most = workers_for_cores(cores);
                assert_eq!(workers_for_memory_on(&host(caches, most, None), most), most);
                assert_eq!(workers_for_memory_on(&host(caches, most, Some(8e9)), most), most);
                assert_eq!(workers_for_memory_on(&host(caches, most, Some(20e6)), most), 1);
            }
        }
    }

    /// gemm's reading of sysfs: L1 and L2 divided by the CPUs sharing them, L3 whole, defaults
    /// where a level is missing; a laptop's and a 480 MiB-L3 server's trees.
    #[test]
    fn cache_figures_are_read_as_gemm_reads_them() {
        let dir = std::env::temp_dir().join(format!("cbd-sysfs-{}", std::process::id()));
        let write_cpu = |root: &std::path::Path, cpu: usize, caches: &[(usize, &str, &str, &str, usize)]| {
            for (k, (level, kind, size, shared, ways)) in caches.iter().enumerate() {
                let index = root.join(format!("cpu{cpu}/cache/index{k}"));
                std::fs::create_dir_all(&index).unwrap();
                for (name, text) in [
                    ("level", level.to_string()),
                    ("type", kind.to_string()),
                    ("size", size.to_string()),
                    ("shared_cpu_list", shared.to_string()),
                    ("ways_of_associativity", ways.to_string()),
                    ("coherency_line_size", "64".to_string()),
                ] {
                    std::fs::write(index.join(name), text).unwrap();
                }
            }
        };
        let server = dir.join("server");
        for cpu in 0..2 {
            let own = cpu.to_string();
            write_cpu(
                &server,
                cpu,
                &[
                    (1, "Data", "48K", &own, 12),
                    (1, "Instruction", "32K", &own, 8),
                    (2, "Unified", "2048K", &own, 16),
                    (3, "Unified", "491520K", "0-1", 16),
                ],
            );
        }
        std::fs::create_dir_all(server.join("cpufreq")).unwrap();
        assert_eq!(CacheSizes::from_sysfs(&server), Some(SERVER));
        let laptop = dir.join("laptop");
        for cpu in 0..4 {
            write_cpu(
                &laptop,
                cpu,
                &[(1, "Data", "32K", &cpu.to_string(), 8), (2, "Unified", "1M", "0-1", 8), (3, "Unified", "8M", "0-3", 16)],
            );
        }
        assert_eq!(CacheSizes::from_sysfs(&laptop), Some(LAPTOP));
        let bare = dir.join("bare");
        std::fs::create_dir_all(bare.join("cpu0")).unwrap();
        assert_eq!(CacheSizes::from_sysfs(&bare), Some(CacheSizes::DEFAULT));
        assert_eq!(CacheSizes::from_sysfs(&dir.join("none")), None);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// With and without a cgroup limit, on this cgroup or an ancestor's (a systemd scope's limit
    /// sits on the scope, not the root), cgroup v2 and v1's memory controller.
    #[test]
    fn cgroup_limits_are_read_up_the_tree() {
        let root = std::env::temp_dir().join(format!("cbd-cgroup-{}", std::process::id()));
        let v2 = "0::/system.slice/run-1.scope\n";
        let scope = root.join("system.slice/run-1.scope");
        std::fs::create_dir_all(&scope).unwrap();
        assert_eq!(cgroup_left_at(&root, v2), None);
        std::fs::write(scope.join("memory.max"), "max\n").unwrap();
        std::fs::write(scope.join("memory.current"), "1000\n").unwrap();
        assert_eq!(cgroup_left_at(&root, v2), None);
        std::fs::write(root.join("system.slice/memory.max"), "536870912\n").unwrap();
        std::fs::write(root.join("system.slice/memory.current"), "36870912\n").unwrap();
        assert_eq!(cgroup_left_at(&root, v2), Some(500e6));
        std::fs::write(scope.join("memory.max"), "300000000\n").unwrap();
        assert_eq!(cgroup_left_at(&root, v2), Some(300e6 - 1000.0));
        // cgroup v1 (a hybrid host): the memory controller's own hierarchy.
        let v1 = "4:memory:/process_api/abc\n1:cpu:/\n0::/\n";
        assert_eq!(cgroup_left_at(&root, v1), None);
        let own = root.join("memory/process_api/abc");
        std::fs::create_dir_all(&own).unwrap();
        std::fs::write(own.join("memory.limit_in_bytes"), "9223372036854771712\n").unwrap();
        assert_eq!(cgroup_left_at(&root, v1), None);
        std::fs::write(root.join("memory/process_api/memory.limit_in_bytes"), "512000000\n").unwrap();
        std::fs::write(root.join("memory/process_api/memory.usage_in_bytes"), "12000000\n").unwrap();
        assert_eq!(cgroup_left_at(&root, v1), Some(500e6));
        // Both at once: the tighter binds.
        assert_eq!(cgroup_left_at(&root, &format!("{v1}{v2}")), Some(300e6 - 1000.0));
        std::fs::remove_dir_all(&root).unwrap();
    }

    #[test]
    fn sysfs_cache_figures_parse() {
        assert_eq!(cache_size("32768K"), Some(32 << 20));
        assert_eq!((cache_size("2M"), cache_size("1G"), cache_size("512")), (Some(2 << 20), Some(1 << 30), Some(512)));
        assert_eq!((cpu_count("0-3,8"), cpu_count("5"), cpu_count("x")), (Some(5), Some(1), None));
    }

    #[test]
    fn commands_run_on_one_bounded_pool() {
        let (inside, nested, fewer) = run_in_pool(2, || {
            (rayon::current_num_threads(), on_workers(7, rayon::current_num_threads), on_workers(1, rayon::current_num_threads))
        })
        .unwrap();
        assert_eq!((inside, nested, fewer), (2, 2, 1), "a fit inside a command runs on its pool, or on fewer workers");
        assert_eq!(run_in_pool(9, rayon::current_num_threads).unwrap(), MAX_WORKERS);
    }
}

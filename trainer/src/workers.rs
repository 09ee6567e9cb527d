//! The worker threads a `cbd` command computes on: one rayon pool, built before the command runs
//! and sized here, so that every parallel piece of faer and of the flow runs on threads the memory
//! check counts. Without it faer's `Par::Rayon` reached rayon's global pool, which has a thread per
//! core (each holding faer's matrix-multiply buffers, `memory::gemm_workspace_bytes`)
//! and panics ("the global thread pool has not been initialized") when its threads cannot start.

use std::sync::OnceLock;

/// Most worker threads: faer's factorisations are split into a fixed two pieces
/// (`numeric::FIXED_SPLIT`), so a third thread would add a workspace and no speed.
pub const MAX_WORKERS: usize = 2;

/// Stack of each worker: the main thread's 8 MiB, since the command runs on a worker.
pub const WORKER_STACK_BYTES: usize = 8 << 20;

/// The pool's size once [`run_in_pool`] has built it.
static WORKERS: OnceLock<usize> = OnceLock::new();

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

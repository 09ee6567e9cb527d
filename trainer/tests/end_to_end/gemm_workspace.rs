//! The memory check's figure for faer's matrix-multiply buffers per thread
//! (`memory::gemm_workspace_bytes`, a copy of gemm's sizing) against what a thread's first multiply
//! really holds at its peak, seen by a global allocator that tracks the live bytes. A faer or gemm that
//! sizes its buffers differently, or a build that links private-gemm-x86 again (a buffer of twice
//! the host's L3 figure whatever the size, issue 48), fails here (issue 27 item 2).

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

struct TracksLive;

static LIVE: AtomicUsize = AtomicUsize::new(0);
static PEAK: AtomicUsize = AtomicUsize::new(0);

// SAFETY: every call is passed to the system allocator unchanged; only the sizes are recorded.
unsafe impl GlobalAlloc for TracksLive {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        let live = LIVE.fetch_add(layout.size(), Ordering::SeqCst) + layout.size();
        PEAK.fetch_max(live, Ordering::SeqCst);
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        LIVE.fetch_sub(layout.size(), Ordering::SeqCst);
        unsafe { System.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static ALLOCATOR: TracksLive = TracksLive;

/// Bytes above what was live before that a fresh thread's one multiply (m × k) · (k × n) holds at
/// its peak (the operands made before; a thread's buffers stay until it ends). The right-hand side
/// is stored transposed, as in a Cholesky factor's update L₂₁ L₂₁ᵀ: gemm packs it then (a
/// column-major one it reads in place).
fn allocated_by_a_multiply(m: usize, k: usize, n: usize) -> usize {
    use faer::{linalg::matmul::matmul, Accum, Mat, Par};
    std::thread::spawn(move || {
        let a = Mat::<f64>::from_fn(m, k, |i, j| ((i * 7 + j * 3) % 11) as f64);
        let b = Mat::<f64>::from_fn(n, k, |i, j| ((i * 5 + j * 2) % 13) as f64);
        let mut c = Mat::<f64>::zeros(m, n);
        let before = LIVE.load(Ordering::SeqCst);
        PEAK.store(before, Ordering::SeqCst);
        matmul(c.as_mut(), Accum::Replace, a.as_ref(), b.transpose(), 1.0, Par::Seq);
        let bytes = PEAK.load(Ordering::SeqCst) - before;
        std::hint::black_box(&c);
        bytes
    })
    .join()
    .unwrap()
}

#[test]
fn memory_check_counts_what_a_threads_first_multiply_allocates() {
    // gemm reads the caches once per process, on its first blocked multiply: not a thread's buffer.
    allocated_by_a_multiply(128, 128, 128);
    // Square, tall-skinny (the evidence's Aᵀ B) and wide shapes, up to the sizes a fit multiplies.
    let shapes = [(16, 16, 16), (64, 64, 64), (256, 256, 256), (1024, 1024, 1024), (200, 4096, 60), (2048, 64, 2048), (3000, 512, 3000)];
    for (m, k, n) in shapes {
        let dim = m.max(k).max(n);
        let allocated = allocated_by_a_multiply(m, k, n) as f64;
        let counted = cbd_trainer::memory::gemm_workspace_bytes(dim);
        eprintln!("{m} × {k} × {n}: allocated {allocated} bytes, counted {counted}");
        assert!(allocated <= counted, "{m}×{k}×{n}: faer's multiply allocated {allocated} bytes, the memory check counts {counted}");
    }
    // The buffers follow the problem: a small multiply allocates no more than its operands' size
    // and the thread's L2 block, never a host-sized buffer.
    let l2 = cbd_trainer::memory::CacheSizes::of_this_host().l2 as f64;
    let small = allocated_by_a_multiply(64, 64, 64) as f64;
    assert!(small <= l2 + 3.0 * 64.0 * 64.0 * 8.0 + 3.0 * 4096.0, "a 64 × 64 multiply allocated {small} bytes (L2 figure {l2})");
    // And the count is not loose where it matters: within 4× (plus the L2 block) at a fit's size.
    let (allocated, counted) = (allocated_by_a_multiply(1024, 1024, 1024) as f64, cbd_trainer::memory::gemm_workspace_bytes(1024));
    assert!(counted <= 4.0 * allocated + l2, "counted {counted} for {allocated} allocated");
}

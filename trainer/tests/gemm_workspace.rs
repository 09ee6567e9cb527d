//! The memory check's figure for faer's matrix-multiply workspace per thread
//! (`memory::gemm_workspace_bytes`, a copy of private-gemm-x86's sizing) against what a
//! thread's first multiply really allocates, seen by a global allocator that records the largest
//! request. A faer or private-gemm-x86 that sizes its buffer differently fails here (issue 27 item 2).

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

struct RecordsLargest;

static LARGEST: AtomicUsize = AtomicUsize::new(0);

// SAFETY: every call is passed to the system allocator unchanged; only the size is recorded.
unsafe impl GlobalAlloc for RecordsLargest {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        LARGEST.fetch_max(layout.size(), Ordering::Relaxed);
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static ALLOCATOR: RecordsLargest = RecordsLargest;

#[test]
fn memory_check_counts_what_a_threads_first_multiply_allocates() {
    use faer::{linalg::matmul::matmul, Accum, Mat, Par};
    let n = 256; // above faer's small-matrix kernels: the blocked multiply and its workspace
    let expected = cbd_trainer::memory::gemm_workspace_bytes();
    let largest = std::thread::spawn(move || {
        let a = Mat::<f64>::from_fn(n, n, |i, j| ((i * 7 + j * 3) % 11) as f64);
        let mut c = Mat::<f64>::zeros(n, n);
        LARGEST.store(0, Ordering::SeqCst);
        matmul(c.as_mut(), Accum::Replace, a.as_ref(), a.as_ref(), 1.0, Par::Seq);
        std::hint::black_box(&c);
        LARGEST.load(Ordering::SeqCst)
    })
    .join()
    .unwrap();
    let private_gemm = cfg!(target_arch = "x86_64") && x86_vector_units();
    if private_gemm {
        assert_eq!(largest as f64, expected, "faer's workspace is {largest} bytes, the memory check counts {expected}");
    } else {
        assert!(largest as f64 <= expected, "faer's workspace is {largest} bytes, more than the {expected} counted");
    }
}

/// Whether faer multiplies with private-gemm-x86 here (AVX-512, or AVX2 with FMA).
fn x86_vector_units() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("avx512f")
            || (std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma"))
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

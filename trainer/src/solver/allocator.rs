//! How glibc malloc keeps freed memory, chosen once per process by the program, never by the
//! library behind its caller's back: the `cbd` binary calls [`crate::cli::configure_allocator`]
//! first thing; a program that links the library and fits wants [`keep_freed_memory`] too.
//!
//! By default `cbd` keeps freed memory in the process instead of returning it to the kernel at
//! once ([`keep_freed_memory`]): a fit allocates and frees the same large blocks (kernel matrices,
//! tangent chunks, factorisations) every iteration; by default each block over 32 MiB is mmap-ed and
//! unmapped again, and the page faults and TLB shootdowns cost about a fifth of a fit at N = 1024 on
//! two cores (measured with perf).
//!
//! Under an address-space limit (`ulimit -v`) the kept memory is what runs out: the heap grows in
//! 64 MiB steps and never shrinks (368 MB of heap for 45 MB of live blocks at N = 576), so an
//! allocation failed (abort) after the memory check had let the fit start. There the CLI asks for
//! [`track_live_memory`]: every block of 1 MiB or more is mapped on its own and returned when freed,
//! one arena for all threads (glibc reserves 64 MiB of address space per thread arena), so the
//! address space follows the live blocks the check counts.

/// Keeps freed memory (`cbd`'s default: faster fits). The first of this and [`track_live_memory`]
/// to run decides for the process; a no-op off glibc.
pub fn keep_freed_memory() {
    configure(false);
}

/// Returns freed memory at once (under an address-space limit). See the module documentation.
pub fn track_live_memory() {
    configure(true);
}

fn configure(frugal: bool) {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    {
        static ONCE: std::sync::Once = std::sync::Once::new();
        ONCE.call_once(|| {
            // SAFETY: mallopt only changes allocator parameters; the values are in range.
            unsafe {
                if frugal {
                    libc::mallopt(libc::M_MMAP_THRESHOLD, 1 << 20);
                    libc::mallopt(libc::M_TRIM_THRESHOLD, 1 << 20);
                    libc::mallopt(libc::M_TOP_PAD, 0);
                    libc::mallopt(libc::M_ARENA_MAX, 1);
                } else {
                    libc::mallopt(libc::M_TRIM_THRESHOLD, 1 << 30);
                    libc::mallopt(libc::M_TOP_PAD, 64 << 20);
                    libc::mallopt(libc::M_MMAP_THRESHOLD, 32 << 20);
                }
            }
        });
    }
    #[cfg(not(all(target_os = "linux", target_env = "gnu")))]
    let _ = frugal;
}

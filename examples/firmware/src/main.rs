//! The calibrated-model runtime on a Cortex-M: loads an embedded blob into static storage,
//! evaluates `shared::COUNT` fixed joint configurations and prints every value's bits through
//! semihosting, in the format of `cbd-fw-host eval` (lines `q…`). Lines `t… TICKS` and
//! `load TICKS` give SysTick ticks per evaluation and for loading; run under
//! `qemu-system-arm -icount shift=0` a tick is 40 guest instructions (see .ci/firmware.sh).
//!
//! Build: `CBD_BLOB=path/to.blob CBD_STORAGE_LEN=… cargo build --release` in this directory;
//! `cargo run --release` runs it on QEMU's Cortex-M7 board.
#![no_std]
#![no_main]

use core::fmt::Write;
use core::hint::black_box;
use core::sync::atomic::{AtomicU32, Ordering};

use cbd_runtime::MAX_JOINTS;
use cbd_runtime::Real;
use cbd_runtime::Calibrator;
use cortex_m::peripheral::{syst::SystClkSource, SYST};
use cortex_m_rt::{entry, exception};
use cortex_m_semihosting::{debug, hio};

#[cfg(not(feature = "panic-never"))]
use panic_semihosting as _;

#[path = "shared.rs"]
mod shared;

include!(concat!(env!("OUT_DIR"), "/storage_len.rs"));

/// The model, in flash; the runtime reads its arrays in place.
static BLOB: &[u8] = include_bytes!(env!("CBD_BLOB_PATH"));

/// All the RAM the runtime uses: `storage_len_for(model)` values of the evaluation scalar (f64, or f32
/// with the feature `f32`): kernel features, the control points' trajectories, working space.
static mut STORAGE: [Real; STORAGE_LEN] = [0.0; STORAGE_LEN];

/// SysTick wrap-arounds (the counter has 24 bits).
static WRAPS: AtomicU32 = AtomicU32::new(0);
const RELOAD: u32 = 0x00FF_FFFF;

#[exception]
fn SysTick() {
    WRAPS.fetch_add(1, Ordering::Relaxed);
}

/// SysTick ticks since start (monotonic, wrap-arounds counted).
fn ticks() -> u64 {
    loop {
        let w = WRAPS.load(Ordering::SeqCst);
        let c = SYST::get_current();
        if WRAPS.load(Ordering::SeqCst) == w {
            return u64::from(w) * u64::from(RELOAD + 1) + u64::from(RELOAD - c);
        }
    }
}

/// Stack use of a query, measured by painting: before each evaluation all the free stack below the
/// current stack pointer (down to the end of `.bss`) is filled with a pattern; after it, the lowest
/// word that no longer holds the pattern is the deepest the evaluation reached. Its distance from
/// the stack pointer before the call is the query's high-water mark (bytes), printed as
/// `stack BYTES` after the `t…` lines. A query that overwrote even the lowest word has run into
/// `.bss` (or could have): its depth is unknown, and the line says so instead of a figure
/// (`.ci/firmware.sh` then fails the check). Painting a fixed 32 KiB window once reported such
/// queries as exactly the window's size (33 024 bytes, six-effects and chain10).
mod stack_paint {
    const PATTERN: u32 = 0xC5C5_C5C5;
    /// Bytes left unpainted right below the stack pointer, for `paint`'s own frame.
    const MARGIN: usize = 256;

    extern "C" {
        /// cortex-m-rt: the first address after `.bss`/`.uninit` (the start of the heap, unused here).
        static mut __sheap: u32;
    }

    /// A painted window `[low, high)` and the stack pointer it was painted under.
    pub struct Painted {
        sp: usize,
        low: usize,
        high: usize,
    }

    /// Paints the window below the current stack pointer (word-aligned).
    #[inline(never)]
    pub fn paint() -> Painted {
        let sp = cortex_m::register::msp::read() as usize;
        let high = sp.saturating_sub(MARGIN) & !3;
        // Only the symbol's address is taken (no read), which needs no `unsafe`.
        let heap_start = core::ptr::addr_of!(__sheap) as usize;
        let low = ((heap_start + 3) & !3).min(high);
        let mut a = low;
        while a < high {
            // SAFETY: [low, high) is free stack below the live frames and above `.bss`.
            unsafe { core::ptr::write_volatile(a as *mut u32, PATTERN) };
            a += 4;
        }
        Painted { sp, low, high }
    }

    /// Bytes of stack used below the painted stack pointer since `paint` (the distance to the
    /// lowest word no longer holding the pattern); `None` when even the lowest painted word was
    /// overwritten (the depth is unknown: the query reached the end of the free stack).
    #[inline(never)]
    pub fn used_since(p: &Painted) -> Option<usize> {
        let mut a = p.low;
        // SAFETY: reads of the painted window, word by word.
        while a < p.high && unsafe { core::ptr::read_volatile(a as *const u32) } == PATTERN {
            a += 4;
        }
        if a == p.low && p.low < p.high {
            return None;
        }
        Some(p.sp.saturating_sub(a))
    }
}

/// A line buffer that never panics (overflow is reported as a fmt error).
struct Line {
    buf: [u8; 1024],
    len: usize,
}

impl Write for Line {
    fn write_str(&mut self, s: &str) -> core::fmt::Result {
        let end = self.len.checked_add(s.len()).ok_or(core::fmt::Error)?;
        self.buf.get_mut(self.len..end).ok_or(core::fmt::Error)?.copy_from_slice(s.as_bytes());
        self.len = end;
        Ok(())
    }
}

impl Line {
    const fn new() -> Self {
        Line { buf: [0; 1024], len: 0 }
    }
    /// Sends the line to the host and empties it.
    fn flush(&mut self, out: &mut hio::HostStream) -> Result<(), ()> {
        let bytes = self.buf.get(..self.len).ok_or(())?;
        self.len = 0;
        out.write_all(bytes)
    }
}

fn run(out: &mut hio::HostStream) -> Result<(), ()> {
    let mut line = Line::new();
    // SAFETY: the only reference to STORAGE, taken once before any other use.
    let storage: &'static mut [Real; STORAGE_LEN] = unsafe { &mut *core::ptr::addr_of_mut!(STORAGE) };
    let t0 = ticks();
    let loaded = Calibrator::load(black_box(BLOB), storage);
    let t1 = ticks();
    let mut cal = match loaded {
        Ok(cal) => cal,
        Err(e) => {
            writeln!(line, "load error: {e}").map_err(|_| ())?;
            line.flush(out)?;
            return Err(());
        }
    };
    writeln!(line, "load {} ticks", t1 - t0).map_err(|_| ())?;
    line.flush(out)?;
    let n = cal.model().n_joints();
    let mut q = [0.0; MAX_JOINTS];
    let q = q.get_mut(..n).ok_or(())?;
    let mut costs = [0u32; shared::COUNT];
    // The deepest query so far; `None` once one exhausted the painted stack.
    let mut stack = Some(0usize);
    for (i, cost) in costs.iter_mut().enumerate() {
        shared::config(i, q);
        let painted = stack_paint::paint();
        let start = ticks();
        #[cfg(not(feature = "transported"))]
        let result = black_box(cal.evaluate(black_box(q)));
        #[cfg(feature = "transported")]
        let result = black_box(cal.evaluate_transported(black_box(q)));
        let end = ticks();
        stack = stack.zip(stack_paint::used_since(&painted)).map(|(a, b)| a.max(b));
        *cost = (end - start) as u32;
        match result {
            Ok(e) => {
                let (pos, jac) = (e.position(), e.jacobian());
                let (m, n) = jac.shape();
                shared::write_result(
                    &mut line,
                    i,
                    pos.iter().copied(),
                    (0..m).flat_map(|a| (0..n).filter_map(move |d| jac.get((a, d)).copied())),
                )
            }
            Err(_) => shared::write_error(&mut line, i),
        }
        .map_err(|_| ())?;
        line.flush(out)?;
        // The tool frame of a model with ≥ 3 tool points (issue 26): its stack counts, its time does not.
        if cal.model().nominal.tool_point_count() >= 3 {
            let painted = stack_paint::paint();
            let pose = black_box(cal.evaluate_pose(black_box(q)));
            stack = stack.zip(stack_paint::used_since(&painted)).map(|(a, b)| a.max(b));
            match pose {
                Ok(p) => shared::write_pose(&mut line, i, &p),
                Err(_) => shared::write_pose_error(&mut line, i),
            }
            .map_err(|_| ())?;
            line.flush(out)?;
        }
    }
    // Compensation (issue 15): the cost of `compensate` alone (its inputs are made before the clock starts).
    let mut compensate_costs = [0u32; shared::COMPENSATE_COUNT];
    let mut seed = [0.0; MAX_JOINTS];
    let mut command = [0.0; MAX_JOINTS];
    let mut target = [0.0; cbd_runtime::MAX_TASK_DIM];
    for (i, cost) in compensate_costs.iter_mut().enumerate() {
        let (seed, command) = (seed.get_mut(..n).ok_or(())?, command.get_mut(..n).ok_or(())?);
        let written = match shared::compensate_inputs(&mut cal, i, seed, &mut target) {
            Ok(m) => {
                let target = target.get(..m).ok_or(())?;
                let painted = stack_paint::paint();
                let start = ticks();
                let result = black_box(cal.compensate(black_box(target), black_box(seed), command));
                let end = ticks();
                stack = stack.zip(stack_paint::used_since(&painted)).map(|(a, b)| a.max(b));
                *cost = (end - start) as u32;
                match result {
                    Ok(c) => shared::write_compensation(&mut line, i, command, &c),
                    Err(_) => shared::write_compensation_error(&mut line, i),
                }
            }
            Err(_) => shared::write_compensation_error(&mut line, i),
        };
        written.map_err(|_| ())?;
        line.flush(out)?;
    }
    for (i, cost) in costs.iter().enumerate() {
        writeln!(line, "t{i:03} {cost}").map_err(|_| ())?;
        line.flush(out)?;
    }
    for (i, cost) in compensate_costs.iter().enumerate() {
        writeln!(line, "ct{i:03} {cost}").map_err(|_| ())?;
        line.flush(out)?;
    }
    match stack {
        Some(bytes) => writeln!(line, "stack {bytes}"),
        None => writeln!(line, "stack unknown: a query overwrote all the free stack it was given"),
    }
    .map_err(|_| ())?;
    line.flush(out)?;
    writeln!(line, "done").map_err(|_| ())?;
    line.flush(out)
}

#[entry]
fn main() -> ! {
    if let Some(mut cp) = cortex_m::Peripherals::take() {
        cp.SYST.set_clock_source(SystClkSource::Core);
        cp.SYST.set_reload(RELOAD);
        cp.SYST.clear_current();
        cp.SYST.enable_interrupt();
        cp.SYST.enable_counter();
    }
    let ok = match hio::hstdout() {
        Ok(mut out) => run(&mut out).is_ok(),
        Err(()) => false,
    };
    debug::exit(if ok { debug::EXIT_SUCCESS } else { debug::EXIT_FAILURE });
    #[allow(clippy::empty_loop)]
    loop {}
}

#[cfg(feature = "panic-never")]
#[panic_handler]
fn panic(_: &core::panic::PanicInfo) -> ! {
    extern "Rust" {
        /// Deliberately undefined: linking fails if any panic is reachable.
        fn cbd_firmware_panic_is_reachable() -> !;
    }
    // SAFETY: never called in a binary that links.
    unsafe { cbd_firmware_panic_is_reachable() }
}

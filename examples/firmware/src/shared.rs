//! Shared by the firmware and `cbd-fw-host` (included with `#[path]` in both), so that both
//! evaluate the same joint configurations and print them in the same format.
//!
//! Everything here is integer arithmetic or exactly rounded IEEE operations: the configurations
//! are bit-identical on every target.

use core::fmt::{self, Write};

/// How many configurations are evaluated.
pub const COUNT: usize = 128;

/// 32-bit linear congruential generator (Numerical Recipes constants).
#[derive(Debug, Clone, Copy)]
pub struct Lcg(pub u32);

impl Lcg {
    pub fn next_u32(&mut self) -> u32 {
        self.0 = self.0.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
        self.0
    }
    /// A value in [0, 1) on a grid of 2⁻²⁴.
    pub fn unit(&mut self) -> f64 {
        (self.next_u32() >> 8) as f64 * (1.0 / 16_777_216.0)
    }
    /// A value in [-1, 1) on a grid of 2⁻²³.
    pub fn symmetric(&mut self) -> f64 {
        2.0 * self.unit() - 1.0
    }
}

/// Query configuration `i` (`0 ≤ i < COUNT`), `out.len()` joints, angles in [-π, π).
pub fn config(i: usize, out: &mut [f64]) {
    let mut rng = Lcg(0x2545_F491 ^ (i as u32).wrapping_mul(0x9E37_79B9));
    for v in out.iter_mut() {
        *v = core::f64::consts::PI * rng.symmetric();
    }
}

/// One result line: `q<i> <position…> | <jacobian, row-major…>`, every value as the 16 hex
/// digits of `f64::to_bits`.
pub fn write_result(w: &mut impl Write, i: usize, position: impl Iterator<Item = f64>, jacobian: impl Iterator<Item = f64>) -> fmt::Result {
    write!(w, "q{i:03}")?;
    for v in position {
        write!(w, " {:016x}", v.to_bits())?;
    }
    w.write_str(" |")?;
    for v in jacobian {
        write!(w, " {:016x}", v.to_bits())?;
    }
    w.write_str("\n")
}

/// The line printed when evaluation `i` fails.
pub fn write_error(w: &mut impl Write, i: usize) -> fmt::Result {
    writeln!(w, "q{i:03} error")
}

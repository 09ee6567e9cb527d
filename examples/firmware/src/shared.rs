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

/// One pose line (models with ≥ 3 tool points, issue 26): `qp<i> <every point's position…> |
/// <rotation, row-major…> <origin…> | <the frame's 6 × n Jacobian, row-major…>`, values as in
/// [`write_result`].
pub fn write_pose(w: &mut impl Write, i: usize, pose: &cbd_runtime::PoseEvaluation) -> fmt::Result {
    write!(w, "qp{i:03}")?;
    for e in (0..pose.point_count()).filter_map(|j| pose.point(j)) {
        for v in e.position().iter() {
            write!(w, " {:016x}", v.to_bits())?;
        }
    }
    w.write_str(" |")?;
    for v in pose.rotation().iter().flatten().chain(pose.origin().iter()) {
        write!(w, " {:016x}", v.to_bits())?;
    }
    w.write_str(" |")?;
    let jac = pose.jacobian();
    let (rows, cols) = jac.shape();
    for (a, d) in (0..rows).flat_map(|a| (0..cols).map(move |d| (a, d))) {
        if let Some(v) = jac.get((a, d)) {
            write!(w, " {:016x}", v.to_bits())?;
        }
    }
    w.write_str("\n")
}

/// The line printed when pose evaluation `i` fails.
pub fn write_pose_error(w: &mut impl Write, i: usize) -> fmt::Result {
    writeln!(w, "qp{i:03} error")
}

/// The line printed when evaluation `i` fails.
pub fn write_error(w: &mut impl Write, i: usize) -> fmt::Result {
    writeln!(w, "q{i:03} error")
}

/// How many compensation cases (issue 15) follow the evaluations.
pub const COMPENSATE_COUNT: usize = 8;

/// Inputs of compensation case `i`: the target is the calibrated position k1 at configuration `i`
/// (reachable by construction), the seed that configuration with every joint moved by +0.05 rad.
/// Writes `seed` (n values) and `target` (m values); returns m.
pub fn compensate_inputs(
    cal: &mut cbd_runtime::Calibrator<'_>,
    i: usize,
    seed: &mut [f64],
    target: &mut [f64; cbd_runtime::MAX_TASK_DIM],
) -> Result<usize, cbd_runtime::Error> {
    config(i, seed);
    let e = cal.evaluate_transported(seed)?;
    let mut m = 0;
    for (t, p) in target.iter_mut().zip(e.position().iter()) {
        *t = *p;
        m += 1;
    }
    for s in seed.iter_mut() {
        *s += 0.05;
    }
    Ok(m)
}

/// One compensation line: `qc<i> <command…> | <residual> <reached><singular><extrapolating>`,
/// values as the 16 hex digits of `f64::to_bits`, flags as 0/1.
pub fn write_compensation(w: &mut impl Write, i: usize, command: &[f64], c: &cbd_runtime::Compensation) -> fmt::Result {
    write!(w, "qc{i:03}")?;
    for v in command {
        write!(w, " {:016x}", v.to_bits())?;
    }
    writeln!(w, " | {:016x} {}{}{}", c.residual.to_bits(), c.reached as u8, c.singular as u8, c.extrapolating as u8)
}

/// The line printed when compensation case `i` fails.
pub fn write_compensation_error(w: &mut impl Write, i: usize) -> fmt::Result {
    writeln!(w, "qc{i:03} error")
}

//! Simulated robots: a nominal model and a "real" arm that differs from it.

pub mod effects;
pub mod rr;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// How to choose configurations.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Sampling {
    /// `per_axis`^n points on a regular grid of the torus, x = 2π i / per_axis.
    Grid { per_axis: usize },
    /// `count` uniform random configurations in [0, 2π)^n.
    Uniform { count: usize, seed: u64 },
}

/// Joint configurations (row-major, n per row) for `n` revolute joints.
pub fn configurations(sampling: Sampling, n: usize) -> Vec<f64> {
    let two_pi = 2.0 * std::f64::consts::PI;
    match sampling {
        Sampling::Grid { per_axis } => {
            let total = per_axis.pow(n as u32);
            let mut out = Vec::with_capacity(total * n);
            for idx in 0..total {
                // Row-major: the first joint varies slowest.
                let mut rem = idx;
                let mut row = vec![0.0; n];
                for d in (0..n).rev() {
                    row[d] = two_pi * (rem % per_axis) as f64 / per_axis as f64;
                    rem /= per_axis;
                }
                out.extend(row);
            }
            out
        }
        Sampling::Uniform { count, seed } => {
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            (0..count * n).map(|_| rng.gen_range(0.0..two_pi)).collect()
        }
    }
}

/// Adds independent Gaussian noise of standard deviation `std` to every value.
pub fn add_noise(values: &mut [f64], std: f64, seed: u64) {
    if std == 0.0 {
        return;
    }
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    for v in values {
        // Box–Muller; deterministic for a seed.
        let u1: f64 = rng.gen_range(f64::EPSILON..1.0);
        let u2: f64 = rng.gen();
        *v += std * (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos();
    }
}

pub mod six_joint;

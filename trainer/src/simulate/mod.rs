//! Simulated robots: a nominal model and a "real" arm that differs from it.

pub mod effects;
pub mod planted;
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
    /// `count` configurations along a random walk in [0, 2π]^n ([`random_walk`]): steps of standard
    /// deviation `step` radians per joint, so consecutive rows are close in joint space.
    Walk { count: usize, step: f64, seed: u64 },
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
        Sampling::Walk { count, step, seed } => random_walk(count, step, &vec![(0.0, two_pi); n], seed),
    }
}

/// `count` configurations (row-major, one per row) along a random walk inside the box `ranges`
/// (lo < hi per joint): the first uniform in the box, each next one the last plus an independent
/// Gaussian step of standard deviation `step` per joint, reflected at the box's faces (a step past
/// hi lands as far below it). Deterministic for a seed. A measurement campaign in the order the
/// arm visits its poses: consecutive rows are close in joint space, as on a real arm's trajectory.
pub fn random_walk(count: usize, step: f64, ranges: &[(f64, f64)], seed: u64) -> Vec<f64> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut q: Vec<f64> = ranges.iter().map(|&(lo, hi)| rng.gen_range(lo..hi)).collect();
    let mut out = Vec::with_capacity(count * ranges.len());
    for row in 0..count {
        if row > 0 {
            for (v, &(lo, hi)) in q.iter_mut().zip(ranges) {
                *v = reflect(*v + step * standard_normal(&mut rng), lo, hi);
            }
        }
        out.extend_from_slice(&q);
    }
    out
}

/// `x` folded into [lo, hi] by reflection at both ends (a mirror of period 2 (hi − lo)).
fn reflect(x: f64, lo: f64, hi: f64) -> f64 {
    let width = hi - lo;
    let period = 2.0 * width;
    let t = (x - lo).rem_euclid(period);
    lo + if t > width { period - t } else { t }
}

/// One standard normal draw ([`normal`] of standard deviation 1).
fn standard_normal(rng: &mut ChaCha8Rng) -> f64 {
    normal(rng, 1.0)
}

/// One normal draw of standard deviation `std` (Box–Muller; deterministic for the generator's
/// seed). `std` multiplies the radius first, as the noise always has (the same bits).
fn normal(rng: &mut ChaCha8Rng, std: f64) -> f64 {
    let u1: f64 = rng.gen_range(f64::EPSILON..1.0);
    let u2: f64 = rng.gen();
    std * (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()
}

/// A stationary Gaussian process over the row sequence, one value per row and coordinate
/// (row-major, `dim` per row): each coordinate an independent AR(1) process — the
/// Ornstein–Uhlenbeck process sampled once per row — with standard deviation `sd` and correlation
/// exp(−|i − j| / `length`) between rows i and j (`length` > 0 rows: the lag over which the
/// correlation falls by e). Exact: x₀ ~ N(0, sd²), x_{i+1} = ρ x_i + sd √(1 − ρ²) ε, ρ = e^{−1/length}.
/// Deterministic for a seed. What `--effect drift` adds and `diagnose::drift` estimates.
pub fn row_drift(rows: usize, dim: usize, sd: f64, length: f64, seed: u64) -> Vec<f64> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let rho = (-1.0 / length).exp();
    let innovation = sd * (1.0 - rho * rho).sqrt();
    let mut x: Vec<f64> = (0..dim).map(|_| sd * standard_normal(&mut rng)).collect();
    let mut out = Vec::with_capacity(rows * dim);
    for row in 0..rows {
        if row > 0 {
            for v in x.iter_mut() {
                *v = rho * *v + innovation * standard_normal(&mut rng);
            }
        }
        out.extend_from_slice(&x);
    }
    out
}

/// Adds independent Gaussian noise of standard deviation `std` to every value.
pub fn add_noise(values: &mut [f64], std: f64, seed: u64) {
    if std == 0.0 {
        return;
    }
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    for v in values {
        *v += normal(&mut rng, std);
    }
}

pub mod six_joint;

#[cfg(test)]
mod tests {
    use super::*;

    /// The walk stays in its box, is deterministic for a seed, and its steps have the stated size
    /// (per-joint RMS of the steps within 5 % of `step` away from the faces).
    #[test]
    fn a_walk_stays_in_its_box_with_steps_of_the_stated_size() {
        let ranges = [(-1.0, 1.0), (0.0, 6.0), (-3.0, 0.5)];
        let q = random_walk(4000, 0.05, &ranges, 7);
        assert_eq!(q, random_walk(4000, 0.05, &ranges, 7));
        assert_ne!(q, random_walk(4000, 0.05, &ranges, 8));
        for row in q.chunks_exact(3) {
            for (v, (lo, hi)) in row.iter().zip(ranges) {
                assert!((lo..=hi).contains(v), "{v} outside [{lo}, {hi}]");
            }
        }
        let rows: Vec<&[f64]> = q.chunks_exact(3).collect();
        for j in 0..3 {
            let steps: Vec<f64> = rows.windows(2).map(|w| w[1][j] - w[0][j]).filter(|d| d.abs() < 0.3).collect();
            let rms = (steps.iter().map(|d| d * d).sum::<f64>() / steps.len() as f64).sqrt();
            assert!((rms / 0.05 - 1.0).abs() < 0.05, "joint {j}: step RMS {rms}");
        }
        // Big steps reflect back in, however far past a face they go.
        assert_eq!(reflect(1.5, 0.0, 1.0), 0.5);
        assert_eq!(reflect(-0.25, 0.0, 1.0), 0.25);
        assert_eq!(reflect(3.25, 0.0, 1.0), 0.75);
    }

    /// The drift's sample autocorrelation against exp(−lag / length), its sample sd against sd
    /// (20 000 rows × 3 coordinates: within a few standard errors).
    #[test]
    fn row_drift_has_the_stated_sd_and_correlation_length() {
        let (rows, sd, length) = (20_000, 0.03, 5.0);
        let x = row_drift(rows, 3, sd, length, 11);
        assert_eq!(x, row_drift(rows, 3, sd, length, 11));
        for c in 0..3 {
            let v: Vec<f64> = x.iter().skip(c).step_by(3).copied().collect();
            let var = v.iter().map(|a| a * a).sum::<f64>() / rows as f64;
            assert!((var.sqrt() / sd - 1.0).abs() < 0.06, "coordinate {c}: sd {}", var.sqrt());
            for lag in [1, 3, 5, 10] {
                let cov = v.windows(lag + 1).map(|w| w[0] * w[lag]).sum::<f64>() / (rows - lag) as f64;
                let expected = (-(lag as f64) / length).exp();
                assert!((cov / var - expected).abs() < 0.06, "coordinate {c}, lag {lag}: {} vs {expected}", cov / var);
            }
        }
    }
}

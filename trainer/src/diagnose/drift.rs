//! Drift: is the residual correlated in the order the rows were measured, beyond what the
//! configuration explains? (docs/DESIGN.md "Drift in measurement order", issue 49.)
//!
//! On a contiguous window of the poses in file order, the residual r (one pose per row, the mean of
//! its points, m coordinates sharing one covariance) is compared under two Gaussian-process priors
//! by type-II maximum likelihood:
//!
//! - H0: K = γ_q exp(Σ_d b_d c_d(q_i, q_j)) + σ² I — a joint-space kernel (the periodic one of §1 per
//!   revolute joint, c = cos Δ − 1; a Gaussian −Δ²/2 in the joint's own spread for a prismatic one)
//!   plus white noise;
//! - H1: the same plus γ_t exp(−|i − j| / L), a stationary process over the row index: the
//!   Ornstein–Uhlenbeck (AR(1)) correlation `simulate::row_drift` plants, so `length` means the
//!   same lag (rows over which the correlation falls by e) in simulation and estimation.
//!
//! Both are maximised with one width per joint; drift is reported when H1's log likelihood exceeds
//! H0's by more than [`DriftOptions::threshold`] nats. The joint kernel is what tells drift from
//! "consecutive poses are close in joint space, so their residuals correlate": on a walk the
//! configuration's share of the correlation is carried by the joint kernel under both hypotheses,
//! and only what follows the row index itself, not the joint distance, raises H1.
//! Drift is a nuisance of the measurement: it never enters a model the runtime evaluates.

use crate::evidence::search::{minimise, Criterion};
use faer::linalg::solvers::{DenseSolveCore, Solve};
use faer::{Mat, Side};
use serde::Serialize;
use std::cell::RefCell;

/// Settings of the drift test.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DriftOptions {
    /// Poses tested (the first this many in file order).
    pub window: usize,
    /// They are cut into contiguous blocks of this many poses, independent under both priors (a
    /// composite likelihood): the cost is O(window · block²) per evaluation instead of O(window³).
    pub block: usize,
    /// Fewer poses than this: no test.
    pub min_poses: usize,
    /// Log-likelihood ratio (nats) H1 must gain over H0 for drift to be reported.
    pub threshold: f64,
}

impl Default for DriftOptions {
    fn default() -> Self {
        DriftOptions { window: 600, block: 600, min_poses: 40, threshold: DETECTION_THRESHOLD }
    }
}

/// Nats H1 must gain. Under H0 the ratio is a supremum over L of a boundary test (γ_t ≥ 0), not
/// χ²: 10 nats (2Δ = 20, a χ²₂ tail of 5e-5) keeps false alarms rare with the joint kernel's own
/// misfit on top (measured on simulated walks without drift: docs/DESIGN.md).
pub const DETECTION_THRESHOLD: f64 = 10.0;

/// What the drift test found.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Drift {
    /// H1 beats H0 by more than `threshold` nats.
    pub detected: bool,
    /// The row-order process's standard deviation per coordinate (model length unit), H1's estimate.
    pub sd: f64,
    /// Its correlation length in rows (poses): correlation exp(−lag / length).
    pub length: f64,
    /// White noise per coordinate under H1.
    pub noise_sd: f64,
    /// White noise per coordinate under H0 (what a model without the row term calls noise).
    pub noise_sd_without_drift: f64,
    /// The joint kernel's standard deviation under H1.
    pub joint_sd: f64,
    /// sd² / (sd² + noise_sd²): the drift's share of the variance a model of the configuration alone
    /// cannot explain (the noise floor such a model reports).
    pub share_of_floor: f64,
    /// log L(H1) − log L(H0), nats.
    pub log_likelihood_ratio: f64,
    pub threshold: f64,
    /// Poses tested (the first ones in file order) and the contiguous blocks they were cut into.
    pub poses: usize,
    pub blocks: usize,
}

impl Drift {
    /// One line of advice.
    pub fn advice(&self) -> &'static str {
        if self.detected {
            "part of the residual follows the order of measurement, not the pose: let the arm settle before each \
             measurement (settle time), warm it up before the campaign, or measure the poses in shuffled order so that \
             drift averages out as noise instead of posing as a shape of the configuration"
        } else {
            "no correlation in measurement order beyond what the configuration explains"
        }
    }
}

/// The window's data in the prior's internal form: residual scaled to unit RMS, per-joint
/// similarity terms c_d(i, j), row distances.
struct Window {
    /// W × m, unit RMS.
    residual: Mat<f64>,
    /// Per joint, W × W: cos Δ − 1 (revolute) or −Δ²/2 in units of the joint's spread (prismatic).
    similarity: Vec<Mat<f64>>,
    /// W × W: |i − j| in rows.
    distance: Mat<f64>,
}

/// The two priors' negative log likelihoods over packed log parameters:
/// H0 [ln b_1 … ln b_n, ln γ_q, ln σ], H1 [ln b_1 … ln b_n, ln γ_q, ln γ_t, ln L, ln σ]: the sum
/// over independent blocks.
struct Likelihood<'a> {
    blocks: &'a [Window],
    with_drift: bool,
}

impl Likelihood<'_> {
    fn evaluate(&self, p: &[f64]) -> Option<(f64, Vec<f64>)> {
        let mut total = (0.0, vec![0.0; p.len()]);
        for window in self.blocks {
            let (v, g) = Block { window, with_drift: self.with_drift }.evaluate(p)?;
            total.0 += v;
            for (t, g) in total.1.iter_mut().zip(g) {
                *t += g;
            }
        }
        Some(total)
    }
}

/// One block's likelihood.
struct Block<'a> {
    window: &'a Window,
    with_drift: bool,
}

impl Block<'_> {
    /// The covariance and its parts at `p`: (K, K_q, K_t).
    fn covariance(&self, p: &[f64]) -> (Mat<f64>, Mat<f64>, Option<Mat<f64>>) {
        let w = self.window;
        let (n, size) = (w.similarity.len(), w.residual.nrows());
        let b: Vec<f64> = p[..n].iter().map(|v| v.exp()).collect();
        let gq = p[n].exp();
        let sigma2 = (2.0 * p[p.len() - 1]).exp();
        let kq = Mat::from_fn(size, size, |i, j| gq * (0..n).map(|d| b[d] * w.similarity[d][(i, j)]).sum::<f64>().exp());
        let kt = self.with_drift.then(|| {
            let (gt, length) = (p[n + 1].exp(), p[n + 2].exp());
            Mat::from_fn(size, size, |i, j| gt * (-w.distance[(i, j)] / length).exp())
        });
        let k = Mat::from_fn(size, size, |i, j| kq[(i, j)] + kt.as_ref().map_or(0.0, |t| t[(i, j)]) + if i == j { sigma2 } else { 0.0 });
        (k, kq, kt)
    }

    /// ½ Σ_c r_cᵀK⁻¹r_c + (m/2) ln|K| + (W m/2) ln 2π, and its gradient ½ Σ_ij (m K⁻¹ − ααᵀ)_ij ∂K_ij.
    fn evaluate(&self, p: &[f64]) -> Option<(f64, Vec<f64>)> {
        let w = self.window;
        let (n, size, m) = (w.similarity.len(), w.residual.nrows(), w.residual.ncols());
        let (k, kq, kt) = self.covariance(p);
        let llt = k.llt(Side::Lower).ok()?;
        let l = llt.L();
        let logdet = 2.0 * (0..size).map(|i| l[(i, i)].ln()).sum::<f64>();
        let alpha = llt.solve(&w.residual);
        let quad: f64 = (0..m).map(|c| (0..size).map(|i| w.residual[(i, c)] * alpha[(i, c)]).sum::<f64>()).sum();
        let value = 0.5 * quad + 0.5 * m as f64 * logdet + 0.5 * (size * m) as f64 * (2.0 * std::f64::consts::PI).ln();
        if !value.is_finite() {
            return None;
        }
        let inverse = llt.inverse();
        let weight =
            Mat::from_fn(size, size, |i, j| m as f64 * inverse[(i, j)] - (0..m).map(|c| alpha[(i, c)] * alpha[(j, c)]).sum::<f64>());
        let trace = |f: &dyn Fn(usize, usize) -> f64| -> f64 {
            0.5 * (0..size).map(|j| (0..size).map(|i| weight[(i, j)] * f(i, j)).sum::<f64>()).sum::<f64>()
        };
        let mut gradient = Vec::with_capacity(p.len());
        for d in 0..n {
            let b = p[d].exp();
            gradient.push(trace(&|i, j| kq[(i, j)] * b * w.similarity[d][(i, j)]));
        }
        gradient.push(trace(&|i, j| kq[(i, j)]));
        if let Some(kt) = &kt {
            let length = p[n + 2].exp();
            gradient.push(trace(&|i, j| kt[(i, j)]));
            gradient.push(trace(&|i, j| kt[(i, j)] * w.distance[(i, j)] / length));
        }
        let sigma2 = (2.0 * p[p.len() - 1]).exp();
        gradient.push(0.5 * (0..size).map(|i| weight[(i, i)]).sum::<f64>() * 2.0 * sigma2);
        Some((value, gradient))
    }
}

impl Criterion for Likelihood<'_> {
    fn observations(&self) -> usize {
        self.blocks.iter().map(|w| w.residual.nrows() * w.residual.ncols()).sum()
    }
    fn nlml_and_gradient(&self, packed: &[f64]) -> Option<(f64, Vec<f64>)> {
        self.evaluate(packed)
    }
    /// Tighter than the evidence's 1e-4 nats per unknown: the test compares two optima, and an
    /// H0 stopped short would show as drift.
    fn tolerances(&self) -> (f64, f64) {
        (1e-7, 1e-6)
    }
}

/// The residual's poses in file order: joints (row-major, n per pose) and the residual (m per pose,
/// the mean over a pose's `points` points).
fn pose_residuals(joints: &[f64], n: usize, residual: &[f64], m: usize, points: usize) -> (Vec<f64>, Vec<f64>) {
    let points = points.max(1);
    let poses = residual.len() / (m * points).max(1);
    let q: Vec<f64> = (0..poses).flat_map(|k| joints[k * points * n..k * points * n + n].to_vec()).collect();
    let r: Vec<f64> = (0..poses)
        .flat_map(|k| (0..m).map(move |c| (0..points).map(|j| residual[(k * points + j) * m + c]).sum::<f64>() / points as f64))
        .collect();
    (q, r)
}

/// The poses `first..first + size` as a block: their residual less its mean per coordinate, over
/// `scale`.
fn window_of(q: &[f64], n: usize, revolute: &[bool], r: &[f64], m: usize, first: usize, size: usize, scale: f64) -> Window {
    let (q, r) = (&q[first * n..(first + size) * n], &r[first * m..(first + size) * m]);
    let mut residual = Mat::from_fn(size, m, |i, c| r[i * m + c]);
    for c in 0..m {
        let mean = (0..size).map(|i| residual[(i, c)]).sum::<f64>() / size as f64;
        for i in 0..size {
            residual[(i, c)] = (residual[(i, c)] - mean) / scale;
        }
    }
    let similarity = (0..n)
        .map(|d| {
            let at = |i: usize| q[i * n + d];
            if revolute.get(d).copied().unwrap_or(true) {
                Mat::from_fn(size, size, |i, j| (at(i) - at(j)).cos() - 1.0)
            } else {
                let mean = (0..size).map(at).sum::<f64>() / size as f64;
                let spread = ((0..size).map(|i| (at(i) - mean).powi(2)).sum::<f64>() / size as f64).sqrt();
                let spread = if spread > 0.0 { spread } else { 1.0 };
                Mat::from_fn(size, size, |i, j| -0.5 * ((at(i) - at(j)) / spread).powi(2))
            }
        })
        .collect();
    let distance = Mat::from_fn(size, size, |i, j| (i as f64 - j as f64).abs());
    Window { residual, similarity, distance }
}

/// The drift test on `residual` (m coordinates per row, `points` rows per pose, in file order) at
/// `joints` (n per row); `None` with fewer than `options.min_poses` poses.
pub fn drift_test(
    joints: &[f64],
    n: usize,
    revolute: &[bool],
    residual: &[f64],
    m: usize,
    points: usize,
    options: &DriftOptions,
) -> Option<Drift> {
    let (q, r) = pose_residuals(joints, n, residual, m, points);
    let poses = r.len() / m.max(1);
    if poses < options.min_poses.max(8) || n == 0 || m == 0 {
        return None;
    }
    let size = poses.min(options.window.max(8));
    // Blocks of about `block` poses (the last one absorbs the remainder).
    let count = (size / options.block.max(8)).max(1);
    let bounds: Vec<(usize, usize)> = (0..count).map(|k| (k * size / count, (k + 1) * size / count - k * size / count)).collect();
    // One scale for every block: the residual's RMS over the window.
    let means: Vec<f64> = (0..m).map(|c| (0..size).map(|i| r[i * m + c]).sum::<f64>() / size as f64).collect();
    let rms = ((0..size * m).map(|k| (r[k] - means[k % m]).powi(2)).sum::<f64>() / (size * m) as f64).sqrt();
    let scale = if rms > 0.0 && rms.is_finite() { rms } else { 1.0 };
    let blocks: Vec<Window> = bounds.iter().map(|&(first, len)| window_of(&q, n, revolute, &r, m, first, len, scale)).collect();
    let longest = bounds.iter().map(|b| b.1).max().unwrap_or(size);
    let evaluations = RefCell::new(0usize);
    let ln = f64::ln;
    // Bounds (log space, the residual at unit RMS): widths from nearly flat to a few degrees,
    // amplitudes and noise from negligible to ten times the residual, L from half a row to half the window.
    let (b_lo, b_hi) = (ln(1e-3), ln(1e3));
    let (g_lo, g_hi) = (ln(1e-6), ln(1e2));
    let (s_lo, s_hi) = (ln(1e-4), ln(10.0));
    let (l_lo, l_hi) = (ln(0.5), ln((longest as f64 / 2.0).max(1.0)));
    let null = Likelihood { blocks: &blocks, with_drift: false };
    let mut lower0 = vec![b_lo; n];
    let mut upper0 = vec![b_hi; n];
    lower0.extend([g_lo, s_lo]);
    upper0.extend([g_hi, s_hi]);
    let start0 = |b: f64| -> Vec<f64> { std::iter::repeat_n(ln(b), n).chain([ln(0.5), ln(0.7)]).collect() };
    let mut best0: Option<(f64, Vec<f64>)> = None;
    for b in [0.5, 5.0] {
        if let Some(found) = minimise(&null, &lower0, &upper0, &start0(b), 400, &evaluations) {
            if best0.as_ref().is_none_or(|(v, _)| found.0 < *v) {
                best0 = Some(found);
            }
        }
    }
    let (nlml0, p0) = best0?;
    let alternative = Likelihood { blocks: &blocks, with_drift: true };
    let (mut lower1, mut upper1) = (lower0[..=n].to_vec(), upper0[..=n].to_vec());
    lower1.extend([g_lo, l_lo, s_lo]);
    upper1.extend([g_hi, l_hi, s_hi]);
    let from_null = |gt: f64, length: f64, joint_share: f64| -> Vec<f64> {
        let mut p = p0[..n].to_vec();
        p.push(p0[n] + ln(joint_share));
        p.extend([ln(gt), ln(length), p0[n + 1]]);
        p
    };
    let mut best1: Option<(f64, Vec<f64>)> = None;
    for start in [from_null(1e-4, 3.0, 1.0), from_null(0.2, 3.0, 0.5), from_null(0.2, 15.0, 0.5), {
        let mut p = start0(0.5);
        p.insert(n + 1, ln(0.3));
        p.insert(n + 2, ln(4.0));
        p
    }] {
        if let Some(found) = minimise(&alternative, &lower1, &upper1, &start, 400, &evaluations) {
            if best1.as_ref().is_none_or(|(v, _)| found.0 < *v) {
                best1 = Some(found);
            }
        }
    }
    let (nlml1, p1) = best1?;
    // H0 is H1's limit γ_t → 0: the ratio is not negative.
    let ratio = (nlml0 - nlml1).max(0.0);
    let (sd, noise_sd) = (p1[n + 1].exp().sqrt() * scale, p1[n + 3].exp() * scale);
    Some(Drift {
        detected: ratio > options.threshold,
        sd,
        length: p1[n + 2].exp(),
        noise_sd,
        noise_sd_without_drift: p0[n + 1].exp() * scale,
        joint_sd: p1[n].exp().sqrt() * scale,
        share_of_floor: sd * sd / (sd * sd + noise_sd * noise_sd),
        log_likelihood_ratio: ratio,
        threshold: options.threshold,
        poses: size,
        blocks: count,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::simulate::{random_walk, row_drift};

    fn small_window(with_drift: bool) -> (Window, Vec<f64>) {
        let n = 3;
        let q = random_walk(60, 0.2, &[(-3.0, 3.0), (-1.0, 1.0), (0.0, 2.0)], 4);
        let mut r = row_drift(60, 3, 1.0, 4.0, 5);
        crate::simulate::add_noise(&mut r, 0.5, 6);
        let window = window_of(&q, n, &[true, true, false], &r, 3, 0, 60, 1.0);
        let p = if with_drift { vec![0.3, -1.0, 0.7, -0.2, -1.1, 1.2, -0.6] } else { vec![0.3, -1.0, 0.7, -0.2, -0.6] };
        (window, p)
    }

    /// The simulated six-joint arm (its DH, base and tool errors; no compliance) measured along a
    /// walk of `count` poses with steps of `step` rad, noise 0.02 mm and drift `sd` over `length`
    /// rows, rows shuffled if `shuffle`; the drift test on the DH fit's residual.
    fn six_walk(seed: u64, count: usize, step: f64, sd: f64, length: f64, shuffle: bool, compliance: bool) -> Drift {
        use crate::simulate::effects::{EffectArm, InjectedEffect};
        use crate::simulate::six_joint::{walk_configurations, SixJointRobot};
        use rand::seq::SliceRandom;
        use rand::SeedableRng;
        let robot = SixJointRobot::ur5_like(1);
        let joints = walk_configurations(count, step, seed);
        let mut data = if compliance {
            let mut robot = robot.clone();
            robot.noise_std = 0.02;
            robot.measure(&joints, seed.wrapping_add(0x5eed))
        } else {
            let arm = EffectArm::new(cbd_protocol::NominalModel::DhChain(robot.real.clone())).with(InjectedEffect::Drift { sd, length });
            arm.measure(&joints, 0.02, seed.wrapping_add(0x5eed))
        };
        if shuffle {
            let mut order: Vec<usize> = (0..data.len()).collect();
            order.shuffle(&mut rand_chacha::ChaCha8Rng::seed_from_u64(seed ^ 0xabc));
            data = data.subset(&order);
        }
        let fit = crate::parametric::calibrate_dh(&robot.nominal, &data, &crate::parametric::DhCalibrationOptions::default()).unwrap();
        let k = crate::nominal::positions(&fit.model, &data.joints, 3);
        let r: Vec<f64> = data.positions.iter().zip(&k).map(|(y, k)| y - k).collect();
        drift_test(&data.joints, 6, &[true; 6], &r, 3, 1, &DriftOptions::default()).unwrap()
    }

    #[test]
    #[ignore]
    fn probe_six_walk() {
        for seed in 1..=std::env::var("SEEDS").ok().and_then(|s| s.parse().ok()).unwrap_or(5u64) {
            let t = std::time::Instant::now();
            let a = six_walk(seed, 600, 0.1, 0.03, 5.0, false, false);
            let ta = t.elapsed().as_secs_f64();
            let b = six_walk(seed, 600, 0.1, 0.03, 5.0, true, false);
            let c = six_walk(seed, 600, 0.1, 0.0, 5.0, false, true);
            println!(
                "seed {seed}: planted Δ {:.1} sd {:.4} L {:.2} noise {:.4} joint {:.4} ({ta:.1} s) | shuffled Δ {:.2} sd {:.4} L {:.2} | none (compliance) Δ {:.2} sd {:.4} L {:.2}",
                a.log_likelihood_ratio, a.sd, a.length, a.noise_sd, a.joint_sd, b.log_likelihood_ratio, b.sd, b.length, c.log_likelihood_ratio, c.sd, c.length
            );
        }
    }

    /// The estimator alone: drift + noise along a walk, no fit before it.
    #[test]
    #[ignore]
    fn probe_no_fit() {
        for seed in 1..=6u64 {
            let q = crate::simulate::six_joint::walk_configurations(600, 0.1, seed);
            let mut r = row_drift(600, 3, 0.03, 5.0, seed);
            crate::simulate::add_noise(&mut r, 0.02, seed + 100);
            let d = drift_test(&q, 6, &[true; 6], &r, 3, 1, &DriftOptions::default()).unwrap();
            println!(
                "seed {seed}: Δ {:.1} sd {:.4} L {:.2} noise {:.4} joint {:.4}",
                d.log_likelihood_ratio, d.sd, d.length, d.noise_sd, d.joint_sd
            );
        }
    }

    /// The analytic gradient against central differences, with and without the row term.
    #[test]
    fn the_gradient_matches_central_differences() {
        for with_drift in [false, true] {
            let (window, p) = small_window(with_drift);
            let blocks = [window];
            let criterion = Likelihood { blocks: &blocks, with_drift };
            crate::evidence::search::assert_gradient_matches_central_differences(&criterion, &p, 1e-6);
        }
    }

    /// The value against the kernel-ridge module's independent log marginal likelihood of the same
    /// covariance (assembled here entry by entry).
    #[test]
    fn the_value_matches_an_independent_log_likelihood() {
        let (window, p) = small_window(true);
        let (value, _) = Block { window: &window, with_drift: true }.evaluate(&p).unwrap();
        let size = window.residual.nrows();
        let e = |k: usize| p[k].exp();
        let k = Mat::from_fn(size, size, |i, j| {
            let joint: f64 = (0..3).map(|d| e(d) * window.similarity[d][(i, j)]).sum();
            e(3) * joint.exp() + e(4) * (-((i as f64) - (j as f64)).abs() / e(5)).exp() + if i == j { e(6) * e(6) } else { 0.0 }
        });
        let lml = crate::baselines::kernel_ridge::selection::log_marginal_likelihood(&k, &window.residual).unwrap();
        assert!((value + lml).abs() < 1e-9 * lml.abs(), "{value} vs {}", -lml);
    }
}

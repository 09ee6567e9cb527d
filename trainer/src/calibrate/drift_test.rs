//! Drift: is the residual correlated in the order the rows were measured, beyond what the
//! configuration explains? (docs/DESIGN.md "Drift in measurement order", issue 49.)
//! Here, in the calibrate layer, because the fit runs it as a stage ([`super::calibrate_rows`]); `cbd diagnose`
//! and `cbd check` read it from above.
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
//! The likelihood is the restricted one (REML, Patterson & Thompson 1971): the residual comes from a
//! fit (the diagnosis' refined parameters, each coordinate's mean), and a fit takes away whatever
//! of the drift its Jacobian's columns can mimic — on a walk the slow part of it, which shortened
//! the estimated length by about a fifth. Only the residual's part orthogonal to those columns,
//! which no value of the fitted parameters changes, is compared: the geometric group marginalised
//! with a flat prior, as the geometry choice does with a broad one (`evidence::GeometricBasis`).
//!
//! Both are maximised with one width per joint; drift is reported when H1's log likelihood exceeds
//! H0's by more than [`DriftOptions::threshold`] nats. The joint kernel is what tells drift from
//! "consecutive poses are close in joint space, so their residuals correlate": on a walk the
//! configuration's share of the correlation is carried by the joint kernel under both hypotheses,
//! and only what follows the row index itself, not the joint distance, raises H1.
//! Drift is a nuisance of the measurement: it never enters a model the runtime evaluates.

use crate::data::Measurements;
use crate::evidence::search::{from_each, minimise, Criterion};
use faer::linalg::solvers::{DenseSolveCore, Solve};
use faer::{Mat, MatRef, Side};
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

/// L-BFGS iterations of each start, and of each run continuing the best starts.
const SCREEN_ITERATIONS: u64 = 15;
const SEARCH_ITERATIONS: u64 = 400;

/// Runs continuing one start, and the gain (nats) below which it is not restarted.
const RESTARTS: usize = 4;
const RESTART_GAIN: f64 = 0.01;

/// A log correlation length within this of its upper bound is "at the bound".
const AT_BOUND: f64 = 1e-2;

/// Shared joint widths b the searches start from (b = 20: about 13° per joint).
const START_WIDTHS: [f64; 3] = [0.5, 5.0, 20.0];

/// Correlation lengths (rows) H1's searches start from, besides the broad start's.
const START_LENGTHS: [f64; 4] = [1.0, 3.0, 10.0, 30.0];

/// What the drift test found.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Drift {
    /// H1 beats H0 by more than `threshold` nats.
    pub detected: bool,
    /// The row-order process's standard deviation per coordinate (model length unit), H1's estimate.
    pub sd: f64,
    /// Its correlation length in rows (poses): correlation exp(−lag / length).
    pub length: f64,
    /// The longest length the search resolves (half its longest block of poses), and whether
    /// `length` ended there: then the row term is a trend over the whole window (warm-up, a slow
    /// thermal change) and `length` is only a lower bound.
    pub length_bound: f64,
    pub length_at_bound: bool,
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
    /// Likelihood evaluations of both searches (the test's cost).
    #[serde(skip)]
    pub evaluations: usize,
}

impl Drift {
    /// The correlation length for a sentence: "8.3 poses", or at the search's bound "≥ 300 poses
    /// (…)", which says that it is a lower bound and what it means.
    pub fn length_text(&self) -> String {
        if self.length_at_bound {
            format!(
                "≥ {:.0} poses (the longest the test resolves in its {} poses: a trend over the campaign, such as warm-up or a slow \
                 thermal change, more than a drift between neighbouring poses)",
                self.length_bound, self.poses
            )
        } else {
            format!("{:.1} poses", self.length)
        }
    }

    /// One line of advice.
    pub fn advice(&self) -> &'static str {
        if self.detected && self.length_at_bound {
            "part of the residual changes slowly over the campaign, not with the pose: warm the arm up before measuring and \
             keep its temperature steady, or measure the poses in shuffled order so that the trend averages out as noise \
             instead of posing as a shape of the configuration"
        } else if self.detected {
            "part of the residual follows the order of measurement, not the pose: let the arm settle before each \
             measurement (settle time), warm it up before the campaign, or measure the poses in shuffled order so that \
             drift averages out as noise instead of posing as a shape of the configuration"
        } else {
            "no correlation in measurement order beyond what the configuration explains"
        }
    }
}

/// The window's data in the prior's internal form: residual scaled to unit RMS, per-joint
/// similarity terms c_d(i, j) and what the fit before the test could absorb.
struct Window {
    /// W × m, unit RMS.
    residual: Mat<f64>,
    /// Per joint, W × W: cos Δ − 1 (revolute) or −Δ²/2 in units of the joint's spread (prismatic).
    similarity: Vec<Mat<f64>>,
    /// An orthonormal basis U (W m × k) of what the residual cannot tell from a change of the
    /// parameters fitted before the test (their Jacobian's columns) or of each coordinate's mean,
    /// as its rows per coordinate: U_c (W × k) holds U's rows m·i + c. The likelihood is the
    /// restricted one (REML): that of the residual's part orthogonal to U, which no fit of those
    /// parameters can change, so the fit cannot take the slow part of a drift away from the test.
    fitted: Vec<Mat<f64>>,
}

/// The two priors' negative log restricted likelihoods over packed log parameters:
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
    /// The covariance and its parts at `p`: K and K_q filled on and below the diagonal only (all
    /// that the Cholesky factorisation and the gradient read), and the row term by lag,
    /// γ_t exp(−t / L) for t = 0 … W − 1.
    fn covariance(&self, p: &[f64]) -> (Mat<f64>, Mat<f64>, Option<Vec<f64>>) {
        let w = self.window;
        let (n, size) = (w.similarity.len(), w.residual.nrows());
        let b: Vec<f64> = p[..n].iter().map(|v| v.exp()).collect();
        let gq = p[n].exp();
        let sigma2 = (2.0 * p[p.len() - 1]).exp();
        let mut kq = Mat::<f64>::zeros(size, size);
        for j in 0..size {
            let column = kq.col_as_slice_mut(j);
            for (d, b) in b.iter().enumerate() {
                for (k, c) in column[j..].iter_mut().zip(&w.similarity[d].col_as_slice(j)[j..]) {
                    *k += b * c;
                }
            }
            for k in &mut column[j..] {
                *k = gq * k.exp();
            }
        }
        let kt = self.with_drift.then(|| {
            let (gt, length) = (p[n + 1].exp(), p[n + 2].exp());
            (0..size).map(|t| gt * (-(t as f64) / length).exp()).collect::<Vec<f64>>()
        });
        let mut k = kq.clone();
        for j in 0..size {
            let column = &mut k.col_as_slice_mut(j)[j..];
            if let Some(kt) = &kt {
                for (k, t) in column.iter_mut().zip(kt) {
                    *k += t;
                }
            }
            column[0] += sigma2;
        }
        (k, kq, kt)
    }

    /// The negative log restricted likelihood of the residual r (W m, coordinate c's column r_c
    /// with covariance K, coordinates independent) given the basis U:
    /// ½ rᵀPr + (m/2) ln|K| + ½ ln|C| + ((W m − k)/2) ln 2π with C = Σ_c U_cᵀK⁻¹U_c and
    /// P = K⁻¹ − K⁻¹U C⁻¹ UᵀK⁻¹ (per coordinate block), and its gradient ½ Σ_ij (Σ_c P_cc − ααᵀ)_ij ∂K_ij,
    /// α_c = (P r)_c (Rasmussen & Williams §2.7 with a flat prior on the fitted directions).
    /// W × W matrices are few and reused (each a fresh allocation costs page faults).
    fn evaluate(&self, p: &[f64]) -> Option<(f64, Vec<f64>)> {
        use faer::linalg::matmul::matmul;
        use faer::{Accum, Par};
        let w = self.window;
        let (n, size, m) = (w.similarity.len(), w.residual.nrows(), w.residual.ncols());
        let (k, kq, kt) = self.covariance(p);
        let llt = k.llt(Side::Lower).ok()?;
        drop(k);
        let logdet = 2.0 * (0..size).map(|i| llt.L()[(i, i)].ln()).sum::<f64>();
        // K⁻¹, then in place Σ_c P_cc − ααᵀ = m K⁻¹ − Σ_c V_c C⁻¹ V_cᵀ − ααᵀ with V_c = K⁻¹U_c.
        let mut weight = llt.inverse();
        drop(llt);
        let mut alpha = Mat::<f64>::zeros(size, m);
        matmul(alpha.as_mut(), Accum::Replace, weight.as_ref(), w.residual.as_ref(), 1.0, Par::Seq);
        let basis = w.fitted.first().map_or(0, |u| u.ncols());
        let mut logdet_c = 0.0;
        let mut v: Vec<Mat<f64>> = Vec::with_capacity(m);
        let mut c_inverse = Mat::<f64>::zeros(basis, basis);
        if basis > 0 {
            let mut c = Mat::<f64>::zeros(basis, basis);
            let mut b = Mat::<f64>::zeros(basis, 1);
            for (col, u) in w.fitted.iter().enumerate() {
                let mut vc = Mat::<f64>::zeros(size, basis);
                matmul(vc.as_mut(), Accum::Replace, weight.as_ref(), u.as_ref(), 1.0, Par::Seq);
                matmul(c.as_mut(), Accum::Add, u.transpose(), vc.as_ref(), 1.0, Par::Seq);
                matmul(b.as_mut(), Accum::Add, vc.transpose(), w.residual.get(.., col..col + 1), 1.0, Par::Seq);
                v.push(vc);
            }
            let c_llt = c.llt(Side::Lower).ok()?;
            logdet_c = 2.0 * (0..basis).map(|i| c_llt.L()[(i, i)].ln()).sum::<f64>();
            let beta = c_llt.solve(&b);
            c_inverse = c_llt.inverse();
            for (col, vc) in v.iter().enumerate() {
                matmul(alpha.get_mut(.., col..col + 1), Accum::Add, vc.as_ref(), beta.as_ref(), -1.0, Par::Seq);
            }
        }
        for j in 0..size {
            for x in weight.col_as_slice_mut(j) {
                *x *= m as f64;
            }
        }
        for vc in &v {
            let vc_c = vc * &c_inverse;
            matmul(weight.as_mut(), Accum::Add, vc_c.as_ref(), vc.transpose(), -1.0, Par::Seq);
        }
        matmul(weight.as_mut(), Accum::Add, alpha.as_ref(), alpha.transpose(), -1.0, Par::Seq);
        let quad: f64 = (0..m).map(|c| (0..size).map(|i| w.residual[(i, c)] * alpha[(i, c)]).sum::<f64>()).sum();
        let value =
            0.5 * quad + 0.5 * m as f64 * logdet + 0.5 * logdet_c + 0.5 * (size * m - basis) as f64 * (2.0 * std::f64::consts::PI).ln();
        if !value.is_finite() {
            return None;
        }
        // ½ Σ_ij W_ij ∂K_ij over the lower triangle (W and ∂K symmetric).
        let mut gradient = vec![0.0; p.len()];
        let b: Vec<f64> = p[..n].iter().map(|v| v.exp()).collect();
        let (mut amplitude, mut lag) = (0.0, 0.0);
        for j in 0..size {
            let (wj, kqj) = (&weight.col_as_slice(j)[j..], &kq.col_as_slice(j)[j..]);
            let joint: f64 = wj.iter().zip(kqj).map(|(wv, kv)| wv * kv).sum::<f64>() - 0.5 * wj[0] * kqj[0];
            gradient[n] += joint;
            for d in 0..n {
                let sim = &w.similarity[d].col_as_slice(j)[j..];
                let sum: f64 = wj.iter().zip(kqj).zip(sim).map(|((wv, kv), sv)| wv * kv * sv).sum::<f64>() - 0.5 * wj[0] * kqj[0] * sim[0];
                gradient[d] += b[d] * sum;
            }
            if let Some(kt) = &kt {
                amplitude += wj.iter().zip(kt).map(|(wv, kv)| wv * kv).sum::<f64>() - 0.5 * wj[0] * kt[0];
                lag += wj.iter().zip(kt).enumerate().map(|(t, (wv, kv))| wv * kv * t as f64).sum::<f64>();
            }
        }
        if kt.is_some() {
            gradient[n + 1] = amplitude;
            gradient[n + 2] = lag / p[n + 2].exp();
        }
        let sigma2 = (2.0 * p[p.len() - 1]).exp();
        gradient[p.len() - 1] = (0..size).map(|i| weight[(i, i)]).sum::<f64>() * sigma2;
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

/// Directions of the fitted parameters kept in the basis: singular values of the unit-column
/// Jacobian with σ² above this fraction of the largest (as the diagnosis' Gauss–Newton steps).
const BASIS_TOLERANCE: f64 = 1e-12;

/// The tested rows one pose each, in file order.
struct Poses {
    /// n per pose.
    q: Vec<f64>,
    n: usize,
    revolute: Vec<bool>,
    /// m per pose: the mean over the pose's points.
    r: Vec<f64>,
    m: usize,
    /// The fitted parameters' Jacobian, m rows per pose (the mean over its points): (poses · m) × p.
    jacobian: Option<Mat<f64>>,
}

impl Poses {
    /// `residual` (m per row, `points` rows per pose) and `fitted` ((rows · m) × p, rows m·i + c)
    /// per pose; `None` when `fitted` does not have a row per residual entry.
    fn new(data: &Measurements, revolute: &[bool], residual: &[f64], fitted: Option<MatRef<'_, f64>>) -> Option<Poses> {
        let (n, m, points) = (data.n_joints, data.task_dim, data.points_per_pose.max(1));
        let poses = (residual.len() / (m * points).max(1)).min(data.joints.len() / (n * points).max(1));
        let q: Vec<f64> = (0..poses).flat_map(|k| data.joints[k * points * n..k * points * n + n].to_vec()).collect();
        let r: Vec<f64> = (0..poses)
            .flat_map(|k| (0..m).map(move |c| (0..points).map(|j| residual[(k * points + j) * m + c]).sum::<f64>() / points as f64))
            .collect();
        let jacobian = match fitted {
            Some(g) if g.nrows() != residual.len() => return None,
            Some(g) => Some(Mat::from_fn(poses * m, g.ncols(), |row, col| {
                let (k, c) = (row / m, row % m);
                (0..points).map(|j| g[((k * points + j) * m + c, col)]).sum::<f64>() / points as f64
            })),
            None => None,
        };
        Some(Poses { q, n, revolute: (0..n).map(|d| revolute.get(d).copied().unwrap_or(true)).collect(), r, m, jacobian })
    }

    fn count(&self) -> usize {
        self.r.len() / self.m.max(1)
    }

    /// The poses `first..first + size` as a block: their residual less its mean per coordinate,
    /// over `scale`; `None` when the basis cannot be factored (non-finite entries) or leaves no
    /// residual degrees of freedom.
    fn window(&self, first: usize, size: usize, scale: f64) -> Option<Window> {
        let (n, m) = (self.n, self.m);
        let (q, r) = (&self.q[first * n..(first + size) * n], &self.r[first * m..(first + size) * m]);
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
                if self.revolute[d] {
                    Mat::from_fn(size, size, |i, j| (at(i) - at(j)).cos() - 1.0)
                } else {
                    let mean = (0..size).map(at).sum::<f64>() / size as f64;
                    let spread = ((0..size).map(|i| (at(i) - mean).powi(2)).sum::<f64>() / size as f64).sqrt();
                    let spread = if spread > 0.0 { spread } else { 1.0 };
                    Mat::from_fn(size, size, |i, j| -0.5 * ((at(i) - at(j)) / spread).powi(2))
                }
            })
            .collect();
        let fitted = self.basis(first, size)?;
        Some(Window { residual, similarity, fitted })
    }

    /// The orthonormal basis of the block's fitted directions (the Jacobian's rows of these poses
    /// and one mean per coordinate), split per coordinate.
    fn basis(&self, first: usize, size: usize) -> Option<Vec<Mat<f64>>> {
        let m = self.m;
        let p = self.jacobian.as_ref().map_or(0, |g| g.ncols());
        let column = |row: usize, col: usize| match &self.jacobian {
            Some(g) if col < p => g[(first * m + row, col)],
            _ => f64::from(u8::from(row % m == col - p)),
        };
        let norms: Vec<f64> = (0..p + m).map(|col| (0..size * m).map(|row| column(row, col).powi(2)).sum::<f64>().sqrt()).collect();
        if size * m <= p + m || norms.iter().any(|v| !v.is_finite()) {
            return None;
        }
        let a = Mat::from_fn(size * m, p + m, |row, col| if norms[col] > 0.0 { column(row, col) / norms[col] } else { 0.0 });
        let svd = a.thin_svd().ok()?;
        let s: Vec<f64> = (0..p + m).map(|k| svd.S()[k]).collect();
        let largest = s.iter().fold(0.0f64, |a, v| a.max(*v));
        let kept: Vec<usize> = (0..p + m).filter(|&k| s[k] > 0.0 && s[k] * s[k] > BASIS_TOLERANCE * largest * largest).collect();
        let u = svd.U();
        Some((0..m).map(|c| Mat::from_fn(size, kept.len(), |i, k| u[(i * m + c, kept[k])])).collect())
    }
}

/// The drift test of a calibration's rows (the fit's noise-floor line and the blob, issue 49 item 2):
/// the residual of `chain` — the nominal or DH-calibrated chain CbD deforms — at `tested`, the first
/// `options.window` poses of the rows in file order (`data::stage_rows::StageRows::drift`), the
/// chain's geometric group marginalised through its identification Jacobian (as `cbd diagnose`
/// marginalises what it refined). `None` with too few poses.
pub fn drift_of_chain(chain: &cbd_protocol::NominalModel, tested: &Measurements, options: &DriftOptions) -> Option<Drift> {
    let residual = tested.residual_of(chain);
    let revolute: Vec<bool> = (0..chain.n_joints()).map(|d| chain.is_revolute(d)).collect();
    let fitted = crate::parametric::identifiable::identification_jacobian(chain, &tested.joints).map(|(jac, _)| jac);
    drift_test(tested, &revolute, &residual, fitted.as_ref().map(|j| j.as_ref()), options)
}

/// The drift test on `residual` (m coordinates per row of `data`, in file order) of a model fitted
/// to these rows, `fitted` the Jacobian of its positions with respect to the fitted parameters
/// ((rows · m) × p, row i coordinate c at m·i + c; `None`: nothing fitted but the mean). `None`
/// with fewer than `options.min_poses` poses, a `fitted` of the wrong height, or nothing the
/// likelihood can be evaluated at.
pub fn drift_test(
    data: &Measurements,
    revolute: &[bool],
    residual: &[f64],
    fitted: Option<MatRef<'_, f64>>,
    options: &DriftOptions,
) -> Option<Drift> {
    let (n, m) = (data.n_joints, data.task_dim);
    if n == 0 || m == 0 {
        return None;
    }
    let all = Poses::new(data, revolute, residual, fitted)?;
    let poses = all.count();
    if poses < options.min_poses.max(8) {
        return None;
    }
    let size = poses.min(options.window.max(8));
    // Blocks of about `block` poses (the last one absorbs the remainder).
    let count = (size / options.block.max(8)).max(1);
    let bounds: Vec<(usize, usize)> = (0..count).map(|k| (k * size / count, (k + 1) * size / count - k * size / count)).collect();
    // One scale for every block: the residual's RMS over the window.
    let r = &all.r;
    let means: Vec<f64> = (0..m).map(|c| (0..size).map(|i| r[i * m + c]).sum::<f64>() / size as f64).collect();
    let rms = ((0..size * m).map(|k| (r[k] - means[k % m]).powi(2)).sum::<f64>() / (size * m) as f64).sqrt();
    let scale = if rms > 0.0 && rms.is_finite() { rms } else { 1.0 };
    let blocks: Vec<Window> = bounds.iter().map(|&(first, len)| all.window(first, len, scale)).collect::<Option<_>>()?;
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
    let alternative = Likelihood { blocks: &blocks, with_drift: true };
    let (mut lower1, mut upper1) = (lower0[..=n].to_vec(), upper0[..=n].to_vec());
    lower1.extend([g_lo, l_lo, s_lo]);
    upper1.extend([g_hi, l_hi, s_hi]);
    // Every start runs SCREEN_ITERATIONS L-BFGS iterations; the best `keep` of them are continued,
    // each restarted from where it stopped until a restart gains less
    // than RESTART_GAIN: L-BFGS stops on a small change of the value, which a backtracked step
    // along a curved valley of the widths also gives, well before the optimum.
    // The starts, and the continued ones, each on the command's workers (`from_each`: a serial
    // loop's results, bit for bit; the test's likelihood runs on one thread).
    let best = |criterion: &Likelihood, lower: &[f64], upper: &[f64], starts: &[Vec<f64>], keep: usize| {
        let run = |start: &[f64], iterations: u64, counted: &RefCell<usize>| minimise(criterion, lower, upper, start, iterations, counted);
        let mut screened: Vec<(f64, Vec<f64>)> =
            from_each(starts, &evaluations, |start, counted| run(start, SCREEN_ITERATIONS, counted)).into_iter().flatten().collect();
        screened.sort_by(|a, b| a.0.total_cmp(&b.0));
        let mut found = screened.first()?.clone();
        screened.truncate(keep);
        let continued = from_each(&screened, &evaluations, |(value, at), counted| {
            let (mut value, mut at) = (*value, at.clone());
            for _ in 0..RESTARTS {
                match run(&at, SEARCH_ITERATIONS, counted) {
                    Some(next) if next.0 < value - RESTART_GAIN => (value, at) = next,
                    Some(next) if next.0 < value => {
                        (value, at) = next;
                        break;
                    }
                    _ => break,
                }
            }
            (value, at)
        });
        for (value, at) in continued {
            if value < found.0 {
                found = (value, at);
            }
        }
        Some(found)
    };
    // Shared widths from broad to narrow: a search that starts narrow lets the joints that need no
    // width widen, one that starts broad seldom narrows a single joint (measured on the UR5 campaign).
    let start0 = |b: f64| -> Vec<f64> { std::iter::repeat_n(ln(b), n).chain([ln(0.5), ln(0.7)]).collect() };
    let (mut nlml0, mut p0) = best(&null, &lower0, &upper0, &START_WIDTHS.map(start0), 2)?;
    // H1 from H0's optimum: with the row term negligible (H1's value there is H0's, so H1's
    // maximum is not below H0's however the other searches end), and with half the noise variance
    // moved into it at lengths from 1 to 30 rows (the likelihood over L has a basin per scale the
    // residual varies on); and from the shared widths with a row term of a few rows.
    let from_null = |p0: &[f64], share: f64, length: f64| -> Vec<f64> {
        let mut p = p0[..=n].to_vec();
        let noise = 2.0 * p0[n + 1];
        match share {
            0.0 => p.extend([g_lo, ln(3.0), p0[n + 1]]),
            _ => p.extend([noise + ln(share), ln(length), 0.5 * (noise + ln(1.0 - share))]),
        }
        p
    };
    let mut starts: Vec<Vec<f64>> = vec![from_null(&p0, 0.0, 3.0)];
    starts.extend(START_LENGTHS.iter().map(|&length| from_null(&p0, 0.5, length.min(l_hi.exp()))));
    starts.extend(START_WIDTHS.iter().map(|&b| {
        let mut p = start0(b);
        p.insert(n + 1, ln(0.3));
        p.insert(n + 2, ln(4.0));
        p
    }));
    let (mut nlml1, mut p1) = best(&alternative, &lower1, &upper1, &starts, 2)?;
    // H0 once more from H1's optimum without the row term (its variance as noise, or as the joint
    // kernel's): an H0 stopped short would pass for drift (on the UR5 campaign H0 gains 17 nats
    // from H1's widths).
    let (gt, noise) = (p1[n + 1].exp(), (2.0 * p1[n + 3]).exp());
    let folded = [[&p1[..=n], &[0.5 * (noise + gt).ln()]].concat(), [&p1[..n], &[(p1[n].exp() + gt).ln(), p1[n + 3]]].concat()];
    if let Some(found) = best(&null, &lower0, &upper0, &folded, 1).filter(|f| f.0 < nlml0) {
        (nlml0, p0) = found;
    }
    // H0 is H1's limit γ_t → 0: where no H1 search reached H0's optimum (H0's second search went
    // further), H1's maximum is taken there, the row term at its lower bound.
    if nlml1 > nlml0 {
        (nlml1, p1) = (nlml0, from_null(&p0, 0.0, 3.0));
    }
    let ratio = (nlml0 - nlml1).max(0.0);
    // A search ended at L's upper bound reports it (a longer L is not resolved in the blocks).
    let length_at_bound = p1[n + 2] >= l_hi - AT_BOUND;
    let (sd, noise_sd) = (p1[n + 1].exp().sqrt() * scale, p1[n + 3].exp() * scale);
    Some(Drift {
        detected: ratio > options.threshold,
        sd,
        length: p1[n + 2].exp(),
        length_bound: l_hi.exp(),
        length_at_bound,
        noise_sd,
        noise_sd_without_drift: p0[n + 1].exp() * scale,
        joint_sd: p1[n].exp().sqrt() * scale,
        share_of_floor: sd * sd / (sd * sd + noise_sd * noise_sd),
        log_likelihood_ratio: ratio,
        threshold: options.threshold,
        poses: size,
        blocks: count,
        evaluations: evaluations.into_inner(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::simulate::{random_walk, row_drift};

    /// 60 poses of a three-joint walk (two revolute, one prismatic) with drift and noise, and a
    /// fitted basis of `fitted` random columns; the packed parameters of one prior.
    fn small_window(with_drift: bool, fitted: usize) -> (Window, Vec<f64>) {
        use rand::{Rng, SeedableRng};
        let n = 3;
        let q = random_walk(60, 0.2, &[(-3.0, 3.0), (-1.0, 1.0), (0.0, 2.0)], 4);
        let mut r = row_drift(60, 3, 1.0, 4.0, 5);
        crate::simulate::add_noise(&mut r, 0.5, 6);
        let data = Measurements {
            n_joints: n,
            task_dim: 3,
            points_per_pose: 1,
            joints: q,
            positions: vec![0.0; r.len()],
            order: crate::data::RowOrder::Measured,
        };
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let g = Mat::from_fn(r.len(), fitted, |_, _| rng.gen_range(-1.0..1.0));
        let poses = Poses::new(&data, &[true, true, false], &r, Some(g.as_ref())).unwrap();
        let window = poses.window(0, 60, 1.0).unwrap();
        let p = if with_drift { vec![0.3, -1.0, 0.7, -0.2, -1.1, 1.2, -0.6] } else { vec![0.3, -1.0, 0.7, -0.2, -0.6] };
        (window, p)
    }

    /// The simulated six-joint arm (its DH, base and tool errors; no compliance) measured along a
    /// walk of 600 poses with steps of 0.1 rad, noise 0.02 mm and drift `sd` over `length`
    /// rows, rows shuffled if `shuffle`; the drift test on the DH fit's residual, the DH parameters
    /// marginalised if `marginalise`.
    fn six_walk(seed: u64, sd: f64, length: f64, shuffle: bool, compliance: bool, marginalise: bool) -> Drift {
        use crate::simulate::effects::{EffectArm, InjectedEffect};
        use crate::simulate::six_joint::{walk_configurations, SixJointRobot};
        use rand::seq::SliceRandom;
        use rand::SeedableRng;
        let robot = SixJointRobot::ur5_like(1);
        let joints = walk_configurations(600, 0.1, seed);
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
        let cbd_protocol::NominalModel::DhChain(chain) = &fit.model else { unreachable!("a DH fit") };
        let g = crate::parametric::geometric_jacobian(chain, &data.joints, 3);
        drift_test(&data, &[true; 6], &r, marginalise.then_some(g.as_ref()), &DriftOptions::default()).unwrap()
    }

    #[test]
    #[ignore]
    fn probe_six_walk() {
        let marginalise = std::env::var("PLAIN").is_err();
        for seed in 1..=std::env::var("SEEDS").ok().and_then(|s| s.parse().ok()).unwrap_or(5u64) {
            let t = std::time::Instant::now();
            let a = six_walk(seed, 0.03, 5.0, false, false, marginalise);
            let ta = t.elapsed().as_secs_f64();
            let b = six_walk(seed, 0.03, 5.0, true, false, marginalise);
            let c = six_walk(seed, 0.0, 5.0, false, true, marginalise);
            println!(
                "seed {seed}: planted Δ {:.1} sd {:.4} L {:.2} noise {:.4} joint {:.4} ({ta:.1} s, {} evaluations) | shuffled Δ {:.2} sd {:.4} L {:.2} | none (compliance) Δ {:.2} sd {:.4} L {:.2}",
                a.log_likelihood_ratio, a.sd, a.length, a.noise_sd, a.joint_sd, a.evaluations, b.log_likelihood_ratio, b.sd, b.length, c.log_likelihood_ratio, c.sd, c.length
            );
        }
    }

    /// The test on a six-joint walk of `rows` poses (steps 0.1 rad) whose residual is drift (`sd` over
    /// `length` rows) plus 0.02 noise, nothing fitted before it.
    fn unfitted_walk(rows: usize, sd: f64, length: f64, seed: u64) -> Drift {
        let q = crate::simulate::six_joint::walk_configurations(rows, 0.1, seed);
        let mut r = row_drift(rows, 3, sd, length, seed);
        crate::simulate::add_noise(&mut r, 0.02, seed + 100);
        let data = Measurements {
            n_joints: 6,
            task_dim: 3,
            points_per_pose: 1,
            joints: q,
            positions: vec![0.0; r.len()],
            order: crate::data::RowOrder::Measured,
        };
        drift_test(&data, &[true; 6], &r, None, &DriftOptions::default()).unwrap()
    }

    /// A row process far slower than the window (a trend over the campaign) ends H1's search at L's
    /// upper bound, half the block: the test says so and gives the length as a lower bound; a
    /// drift of a few rows does not.
    #[test]
    fn a_length_at_the_searchs_bound_is_reported_as_a_lower_bound() {
        let rows = 200;
        for (length, at_bound) in [(400.0, true), (3.0, false)] {
            let d = unfitted_walk(rows, 0.1, length, 5);
            errln!("planted length {length}: found {:.1} (Δ {:.1} nats): over {}", d.length, d.log_likelihood_ratio, d.length_text());
            assert!(d.detected, "planted length {length}: {d:?}");
            assert!((d.length_bound - 100.0).abs() < 1e-9, "{}", d.length_bound);
            assert_eq!(d.length_at_bound, at_bound, "planted length {length}: found {}", d.length);
            assert_eq!(d.length_text().starts_with("≥ 100 poses"), at_bound, "{}", d.length_text());
        }
    }

    /// The estimator alone: drift + noise along a walk, no fit before it.
    #[test]
    #[ignore]
    fn probe_no_fit() {
        for seed in 1..=6u64 {
            let d = unfitted_walk(600, 0.03, 5.0, seed);
            println!(
                "seed {seed}: Δ {:.1} sd {:.4} L {:.2} noise {:.4} joint {:.4}",
                d.log_likelihood_ratio, d.sd, d.length, d.noise_sd, d.joint_sd
            );
        }
    }

    /// A fit before the test takes the slow part of a drift: here 8 slow cosines of the row index
    /// per coordinate (periods of 75 rows and longer, what a geometric fit along a walk can mimic)
    /// fitted by least squares and removed. Against the length the same test gives on the rows
    /// before that fit, the ordinary likelihood of what is left calls the drift shorter; the
    /// restricted one, given the cosines, does not.
    #[test]
    fn marginalising_the_fitted_columns_removes_the_length_bias() {
        let (rows, m, k) = (300, 3, 8);
        let (mut restricted, mut plain) = (Vec::new(), Vec::new());
        for seed in 1..=4u64 {
            let q = crate::simulate::six_joint::walk_configurations(rows, 0.1, seed);
            let mut r = row_drift(rows, m, 1.0, 5.0, seed);
            crate::simulate::add_noise(&mut r, 0.5, seed + 100);
            let g = Mat::from_fn(rows * m, m * k, |row, col| {
                let (i, c, f) = (row / m, row % m, col / m);
                if col % m == c {
                    (std::f64::consts::PI * (f + 1) as f64 * (i as f64 + 0.5) / rows as f64).cos()
                } else {
                    0.0
                }
            });
            let rhs = Mat::from_fn(rows * m, 1, |i, _| r[i]);
            let beta = (g.transpose() * &g).llt(Side::Lower).unwrap().solve(g.transpose() * &rhs);
            let fit = &g * &beta;
            let left: Vec<f64> = (0..rows * m).map(|i| r[i] - fit[(i, 0)]).collect();
            let data = Measurements {
                n_joints: 6,
                task_dim: m,
                points_per_pose: 1,
                joints: q,
                positions: vec![0.0; rows * m],
                order: crate::data::RowOrder::Measured,
            };
            let options = DriftOptions { window: rows, block: rows, ..DriftOptions::default() };
            let before = drift_test(&data, &[true; 6], &r, None, &options).unwrap().length;
            restricted.push(drift_test(&data, &[true; 6], &left, Some(g.as_ref()), &options).unwrap().length / before);
            plain.push(drift_test(&data, &[true; 6], &left, None, &options).unwrap().length / before);
        }
        let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
        assert!((mean(&restricted) - 1.0).abs() < 0.1, "over the length before the fit: restricted {restricted:?}, plain {plain:?}");
        assert!(mean(&plain) < 0.8, "over the length before the fit: restricted {restricted:?}, plain {plain:?}");
    }

    /// A Jacobian without a row per residual entry: no test, no panic.
    #[test]
    fn a_fitted_jacobian_of_the_wrong_height_is_refused() {
        let (window, _) = small_window(true, 0);
        let data = Measurements {
            n_joints: 3,
            task_dim: 3,
            points_per_pose: 1,
            joints: vec![0.0; 180],
            positions: vec![0.0; 180],
            order: crate::data::RowOrder::Measured,
        };
        let r: Vec<f64> = (0..180).map(|i| window.residual[(i / 3, i % 3)]).collect();
        let g = Mat::<f64>::zeros(179, 2);
        assert!(drift_test(&data, &[true; 3], &r, Some(g.as_ref()), &DriftOptions::default()).is_none());
        let g = Mat::from_fn(180, 2, |i, _| if i == 7 { f64::NAN } else { 1.0 });
        assert!(drift_test(&data, &[true; 3], &r, Some(g.as_ref()), &DriftOptions::default()).is_none());
    }

    /// The analytic gradient against central differences, with and without the row term, with
    /// and without fitted columns.
    #[test]
    fn the_gradient_matches_central_differences() {
        for with_drift in [false, true] {
            for fitted in [0, 5] {
                let (window, p) = small_window(with_drift, fitted);
                let blocks = [window];
                let criterion = Likelihood { blocks: &blocks, with_drift };
                crate::evidence::search::assert_gradient_matches_central_differences(&criterion, &p, 1e-6);
            }
        }
    }

    /// The basis is orthonormal and spans the fitted columns and the means.
    #[test]
    fn the_basis_is_orthonormal_and_spans_the_fitted_columns() {
        let (window, _) = small_window(true, 5);
        let (size, m) = (window.residual.nrows(), window.residual.ncols());
        let u = Mat::from_fn(size * m, window.fitted[0].ncols(), |row, k| window.fitted[row % m][(row / m, k)]);
        assert_eq!(u.ncols(), 5 + m);
        let gram = u.transpose() * &u;
        for i in 0..u.ncols() {
            for j in 0..u.ncols() {
                assert!((gram[(i, j)] - f64::from(u8::from(i == j))).abs() < 1e-12, "UᵀU[{i},{j}] = {}", gram[(i, j)]);
            }
        }
        // The same random columns as `small_window`'s, and the means: U Uᵀ leaves them unchanged.
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let g = Mat::from_fn(size * m, 5, |_, _| rng.gen_range(-1.0..1.0));
        let means = Mat::from_fn(size * m, m, |row, c| f64::from(u8::from(row % m == c)));
        for a in [g, means] {
            let projected = &u * (u.transpose() * &a);
            let worst = (0..a.nrows())
                .flat_map(|i| (0..a.ncols()).map(move |k| (i, k)))
                .map(|(i, k)| (projected[(i, k)] - a[(i, k)]).abs())
                .fold(0.0, f64::max);
            assert!(worst < 1e-12, "{worst}");
        }
    }

    /// The value against an independent route: the ordinary log likelihood (the kernel-ridge
    /// module's) of the residual's part orthogonal to the basis, Qᵀr ~ N(0, QᵀK Q) with Q an
    /// orthonormal complement of U from an eigendecomposition of I − UUᵀ and K assembled entry by
    /// entry over all W m coordinates — with and without fitted columns (then U spans the means).
    #[test]
    fn the_value_matches_an_independent_log_likelihood() {
        for fitted in [0, 5] {
            let (window, p) = small_window(true, fitted);
            let (value, _) = Block { window: &window, with_drift: true }.evaluate(&p).unwrap();
            let (size, m) = (window.residual.nrows(), window.residual.ncols());
            let e = |k: usize| p[k].exp();
            let k = Mat::from_fn(size * m, size * m, |a, b| {
                let (i, j) = (a / m, b / m);
                if a % m != b % m {
                    return 0.0;
                }
                let joint: f64 = (0..3).map(|d| e(d) * window.similarity[d][(i, j)]).sum();
                e(3) * joint.exp() + e(4) * (-((i as f64) - (j as f64)).abs() / e(5)).exp() + if i == j { e(6) * e(6) } else { 0.0 }
            });
            let u = Mat::from_fn(size * m, window.fitted[0].ncols(), |row, k| window.fitted[row % m][(row / m, k)]);
            let complement = Mat::<f64>::identity(size * m, size * m) - &u * u.transpose();
            let evd = complement.self_adjoint_eigen(Side::Lower).unwrap();
            let keep: Vec<usize> = (0..size * m).filter(|&i| evd.S()[i] > 0.5).collect();
            assert_eq!(keep.len(), size * m - u.ncols());
            let q = Mat::from_fn(size * m, keep.len(), |row, c| evd.U()[(row, keep[c])]);
            let r = Mat::from_fn(size * m, 1, |row, _| window.residual[(row / m, row % m)]);
            let (kq, rq) = (q.transpose() * &k * &q, q.transpose() * &r);
            let lml = crate::baselines::kernel_ridge::selection::log_marginal_likelihood(&kq, &rq).unwrap();
            assert!((value + lml).abs() < 1e-9 * lml.abs(), "{fitted} columns: {value} vs {}", -lml);
        }
    }
}

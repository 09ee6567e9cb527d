//! Kernel widths and noise chosen objectively: maximise the log marginal likelihood of the
//! Gaussian-process model of the residual r(x) = (y − k0(x)) / scale (docs/DESIGN.md §9).
//!
//! Model: each task coordinate of r is an independent GP with the same covariance
//! γ K_V(x, x') + σ² δ, K_V the joint kernel with γ = 1 (periodic axes b (cos Δ − 1), Gaussian
//! axes −Δ²/(2ℓ²)). The signal variance γ is profiled out in closed form; the search runs over
//! log b_d (or log ℓ_d) — shared by all axes or per axis — and log(σ²/γ), by a deterministic
//! coordinate (pattern) search with shrinking steps on at most `max_points` evenly spaced rows;
//! when that is a subset and every joint is revolute, its choice is refined on every row in weight
//! space ([`super::weight_space`], as CbD's evidence is). Only the rows given are used: pass
//! training rows, never test rows.
//!
//! For [`super::KernelRidge::fit`], predictions depend only on ridge / γ, so
//! `KernelRidge::fit(nominal, data, h.kernel.clone(), h.ridge())` is the GP posterior mean
//! whatever the units of `data` ([`super::fit_kernel_ridge_peer`] does both).

#[cfg(test)]
use super::fit::kernel_matrix;
use super::weight_space::{refine, KrrWeightSpaceReport};
use crate::axis_forms::{axes_at, forms_of, AxisForm};
use crate::data::Measurements;
use crate::evidence::joint_pair_table::JointPairTable;
use crate::numeric::likelihood_search::{LikelihoodSearch::KernelRidge, MIN_SEARCH_ROWS};
use cbd_protocol::{JointKernel, NominalModel, Normalisation};
use cbd_runtime::internals::kinematics::forward_kinematics;
use faer::{linalg::solvers::Solve, Mat, Side};

/// Search settings.
#[derive(Debug, Clone, PartialEq)]
pub struct SearchOptions {
    /// Positions are divided by this before the GP sees them; `None`: the scale of
    /// [`crate::data::Measurements::normalisation`] (RMS distance of the measured positions from their mean),
    /// the same normalisation the CbD model uses.
    pub task_scale: Option<f64>,
    /// After the shared-width search, refine each joint's width separately.
    pub per_axis: bool,
    /// Starting periodic b (and Gaussian width ℓ); `None`: from the data, so that the kernel
    /// between two typical training configurations is about ½.
    pub initial_b: Option<f64>,
    pub initial_width: Option<f64>,
    /// Coarse grid before the pattern search: factors 4^k (|k| ≤ this) on the shared widths,
    /// times noise ratios σ²/γ = 10^-10, 10^-8, …, 10^2.
    pub grid_half_width: i32,
    /// Bounds on log-parameters keep the search in a sane box.
    pub b_range: (f64, f64),
    pub noise_ratio_range: (f64, f64),
    /// The pattern search stops after this many likelihood evaluations in all (each one N×N
    /// Cholesky factorisation); the coarse grid always runs ((2·grid_half_width + 1) × 7).
    pub max_evaluations: usize,
    /// Use at most this many rows (evenly spaced) for the kernel form's search.
    pub max_points: usize,
    /// When that is a subset, refine its choice on every row in weight space if the truncated
    /// periodic expansion needs at most this many functions (each evaluation O(r³ + N r m)).
    pub max_weight_space_weights: usize,
}

impl Default for SearchOptions {
    fn default() -> Self {
        SearchOptions {
            task_scale: None,
            per_axis: true,
            initial_b: None,
            initial_width: None,
            grid_half_width: 3,
            b_range: (1e-3, 1e3),
            noise_ratio_range: (1e-12, 1e2),
            max_evaluations: 150,
            max_points: 1500,
            max_weight_space_weights: 1200,
        }
    }
}

/// The chosen hyperparameters, in normalised units (positions / `task_scale`).
#[derive(Debug, Clone, PartialEq)]
pub struct Hyperparameters {
    /// Joint kernel; `gamma` is the fitted signal variance γ.
    pub kernel: JointKernel,
    /// Noise standard deviation σ (normalised units; σ · task_scale in the data's unit).
    pub noise_sigma: f64,
    pub task_scale: f64,
    /// Log marginal likelihood at the choice (all coordinates, rows used).
    pub log_marginal_likelihood: f64,
    /// The kernel form's likelihood evaluations (each an N × N Cholesky factorisation).
    pub evaluations: usize,
    /// Rows the chosen θ's likelihood was computed on: every row when refined in weight space.
    pub rows_used: usize,
    /// The refinement on every row, when the kernel form's search took a subset.
    pub weight_space: Option<KrrWeightSpaceReport>,
    /// Why a subset's choice was not refined on every row.
    pub weight_space_declined: Option<String>,
}

impl Hyperparameters {
    /// Ridge for [`super::KernelRidge::fit`] with `self.kernel`: σ².
    pub fn ridge(&self) -> f64 {
        self.noise_sigma * self.noise_sigma
    }
    /// Noise standard deviation in the data's length unit.
    pub fn noise_sigma_data_units(&self) -> f64 {
        scale_only(self.task_scale).length_to_user(self.noise_sigma)
    }
}

/// Why kernel ridge's hyperparameter search found none (the search named: kernel ridge's).
pub type HyperparameterError = crate::numeric::likelihood_search::LikelihoodSearchError;

/// Log marginal likelihood of independent GP coordinates `residual` (N × m) with covariance
/// `k` (N × N, noise included): −½ Σ_c r_cᵀ K⁻¹ r_c − (m/2) log|K| − (N m/2) log 2π.
/// `None` if `k` is not positive definite.
pub fn log_marginal_likelihood(k: &Mat<f64>, residual: &Mat<f64>) -> Option<f64> {
    let (n, m) = (residual.nrows(), residual.ncols());
    let llt = k.llt(Side::Lower).ok()?;
    let l = llt.L();
    let logdet: f64 = (0..n).map(|i| l[(i, i)].ln()).sum::<f64>() * 2.0;
    let alpha = llt.solve(residual);
    let quad: f64 = (0..n).flat_map(|i| (0..m).map(move |c| (i, c))).map(|(i, c)| residual[(i, c)] * alpha[(i, c)]).sum();
    Some(-0.5 * quad - 0.5 * m as f64 * logdet - 0.5 * (n * m) as f64 * (2.0 * std::f64::consts::PI).ln())
}

/// Profiled log marginal likelihood for unit-γ kernel matrix `c` and noise ratio λ = σ²/γ:
/// returns (value, γ̂).
pub fn profiled_lml(c: &Mat<f64>, residual: &Mat<f64>, lambda: f64) -> Option<(f64, f64)> {
    let (n, m) = (residual.nrows(), residual.ncols());
    let mut k = c.clone();
    for i in 0..n {
        k[(i, i)] += lambda;
    }
    let llt = k.llt(Side::Lower).ok()?;
    let l = llt.L();
    let logdet: f64 = (0..n).map(|i| l[(i, i)].ln()).sum::<f64>() * 2.0;
    let alpha = llt.solve(residual);
    let quad: f64 = (0..n).flat_map(|i| (0..m).map(move |c| (i, c))).map(|(i, c)| residual[(i, c)] * alpha[(i, c)]).sum();
    let nm = (n * m) as f64;
    let gamma = quad / nm;
    if !(gamma > 0.0) || !logdet.is_finite() {
        return None;
    }
    let value = -0.5 * nm * gamma.ln() - 0.5 * m as f64 * logdet - 0.5 * nm - 0.5 * nm * (2.0 * std::f64::consts::PI).ln();
    Some((value, gamma))
}

/// The kernel for log-parameters `theta` (one per axis of `forms`) and amplitude γ.
fn kernel_of(forms: &[&dyn AxisForm], theta: &[f64], gamma: f64) -> JointKernel {
    let axes = axes_at(forms, theta);
    JointKernel { gamma, axes: heapless::Vec::from_slice(&axes).expect("at most MAX_JOINTS axes") }
}

/// Kernel ridge's own hyperparameters: the joint-kernel widths, γ and σ that maximise its GP's
/// marginal likelihood on the residual of `nominal` on `data`.
pub fn choose_kernel_ridge_hyperparameters(
    nominal: &NominalModel,
    data: &Measurements,
    options: &SearchOptions,
) -> Result<Hyperparameters, HyperparameterError> {
    let count = data.len();
    if count < MIN_SEARCH_ROWS {
        return Err(HyperparameterError::TooFewRows(KernelRidge, count));
    }
    let n = data.n_joints;
    let rows = crate::data::evenly_spaced_rows(count, options.max_points);
    let used = data.subset(&rows);
    let task_scale = options.task_scale.unwrap_or_else(|| data.normalisation().task_scale);
    let residual = normalised_residual(nominal, &used, task_scale);
    let table = JointPairTable::new(forms_of(nominal), &used);
    let init = data_start(&table, options);
    let gp = ResidualGp { table, residual, evaluations: std::cell::Cell::new(0) };
    let bounds = Bounds {
        width: (options.b_range.0.ln(), options.b_range.1.ln()),
        noise: (options.noise_ratio_range.0.ln(), options.noise_ratio_range.1.ln()),
    };
    let Some(mut point) = grid_search(&gp, &init, &bounds, options.grid_half_width) else {
        return Err(HyperparameterError::NoValidSetting(KernelRidge));
    };
    pattern_search(&gp, &mut point, &bounds, options);
    let (mut theta, mut log_lambda, mut gamma, mut lml, mut rows_used) =
        (point.theta.clone(), point.log_lambda, point.value.1, point.value.0, used.len());
    let (mut weight_space, mut weight_space_declined) = (None, None);
    if used.len() < count {
        // Every row, in weight space (as CbD's evidence): (ln b_d, ln λ) from the subset's choice.
        let start: Vec<f64> = point.theta.iter().copied().chain([point.log_lambda]).collect();
        let lower: Vec<f64> = (0..=n).map(|k| if k < n { bounds.width.0 } else { bounds.noise.0 }).collect();
        let upper: Vec<f64> = (0..=n).map(|k| if k < n { bounds.width.1 } else { bounds.noise.1 }).collect();
        let all = normalised_residual(nominal, data, task_scale);
        match refine(nominal, data, &all, &start, &lower, &upper, options.max_weight_space_weights, (used.len(), point.value.0)) {
            Ok(r) => {
                (theta, log_lambda, gamma, lml, rows_used) = (r.param[..n].to_vec(), r.param[n], r.gamma, -r.nlml, count);
                weight_space = Some(r.report);
            }
            Err(why) => weight_space_declined = Some(why.to_string()),
        }
    }
    Ok(Hyperparameters {
        kernel: kernel_of(&gp.table.forms, &theta, gamma),
        noise_sigma: (log_lambda.exp() * gamma).sqrt(),
        task_scale,
        log_marginal_likelihood: lml,
        evaluations: gp.evaluations.get(),
        rows_used,
        weight_space,
        weight_space_declined,
    })
}

/// The residual (y − k0(q)) / `task_scale` of every row of `data` (N × m).
pub fn normalised_residual(nominal: &NominalModel, data: &Measurements, task_scale: f64) -> Mat<f64> {
    let nominal_positions: Vec<[f64; 3]> = (0..data.len()).map(|i| forward_kinematics(nominal, data.joints(i)).position).collect();
    let norm = scale_only(task_scale);
    Mat::from_fn(data.len(), data.task_dim, |i, c| norm.length_to_internal(data.position(i)[c] - nominal_positions[i][c]))
}

/// Kernel ridge's normalisation: its residuals are differences, so only the scale applies.
fn scale_only(task_scale: f64) -> Normalisation {
    Normalisation { task_scale, ..Normalisation::IDENTITY }
}

/// Log widths where typical pairs of rows have kernel ½ ([`JointPairTable::half_kernel_log_widths`]
/// over up to 200 pairs (i, 7919 i + 1 mod N)), unless the options give a start.
fn data_start(table: &JointPairTable, options: &SearchOptions) -> Vec<f64> {
    let count = table.count;
    let pairs = (0..count.min(200)).map(|i| JointPairTable::pair_index(i, (i * 7919 + 1) % count));
    let half = table.half_kernel_log_widths(pairs);
    // The given start: b for the periodic forms, the width for the others.
    let given = |f: &&dyn AxisForm| if f.periodic() { options.initial_b } else { options.initial_width };
    table.forms.iter().zip(half).map(|(f, l)| given(f).map_or(l, f64::ln)).collect()
}

/// The GP on the residual for one joint kernel, its profiled marginal likelihood counted per call.
struct ResidualGp {
    /// The kernel's exponent per pair of rows and axis: each evaluation costs one exp per pair.
    table: JointPairTable,
    residual: Mat<f64>,
    evaluations: std::cell::Cell<usize>,
}

impl ResidualGp {
    /// (log marginal likelihood, γ) at log widths `theta` and log noise ratio `log_lambda`.
    fn eval(&self, theta: &[f64], log_lambda: f64) -> Option<(f64, f64)> {
        self.evaluations.set(self.evaluations.get() + 1);
        let count = self.table.count;
        let w = self.table.axis_weights(theta);
        let mut c = Mat::<f64>::zeros(count, count);
        let mut at = 0;
        for i in 0..count {
            for j in 0..=i {
                let v = self.table.unit_kernel(at, &w);
                c[(i, j)] = v;
                c[(j, i)] = v;
                at += 1;
            }
        }
        profiled_lml(&c, &self.residual, log_lambda.exp())
    }
}

/// Log bounds of the widths (b, or ℓ) and of the noise ratio λ.
struct Bounds {
    width: (f64, f64),
    noise: (f64, f64),
}

/// The best point found so far.
struct SearchPoint {
    /// (log marginal likelihood, γ).
    value: (f64, f64),
    theta: Vec<f64>,
    log_lambda: f64,
}

/// Coarse grid on (shared width factor, noise ratio). A wider periodic kernel has smaller b, a
/// wider Gaussian one larger ℓ: the factor multiplies every form's weight alike (b, 1/ℓ²).
fn grid_search(gp: &ResidualGp, init: &[f64], bounds: &Bounds, half_width: i32) -> Option<SearchPoint> {
    let (lo_b, hi_b) = bounds.width;
    let shift =
        |k: f64| -> Vec<f64> { init.iter().zip(&gp.table.forms).map(|(t, f)| (t + k / f.log_weight_slope()).clamp(lo_b, hi_b)).collect() };
    let mut best: Option<SearchPoint> = None;
    for k in -half_width..=half_width {
        let th = shift(k as f64 * 4f64.ln());
        for e in (-10..=2).step_by(2) {
            let ll = (10f64.powi(e)).ln().clamp(bounds.noise.0, bounds.noise.1);
            if let Some(v) = gp.eval(&th, ll) {
                if best.as_ref().map_or(true, |b| v.0 > b.value.0) {
                    best = Some(SearchPoint { value: v, theta: th.clone(), log_lambda: ll });
                }
            }
        }
    }
    best
}

/// Compass search from `point` within the evaluation budget: λ and the shared width first, then
/// (per axis) every axis alone; steps from a factor 2 halving down to 5 %.
fn pattern_search(gp: &ResidualGp, point: &mut SearchPoint, bounds: &Bounds, options: &SearchOptions) {
    let n = gp.table.forms.len();
    let (lo_b, hi_b) = bounds.width;
    let budget = options.max_evaluations.max(4);
    // Coordinates: 0 = λ, 1 = shared width (all axes), 2.. = single axes (second phase).
    let phases: Vec<Vec<usize>> =
        if options.per_axis && n > 1 { vec![vec![0, 1], (0..=n + 1).filter(|&k| k != 1).collect()] } else { vec![vec![0, 1]] };
    for coords in phases {
        let mut step = 2f64.ln(); // factor 2, then halving
        while step > 1.05f64.ln() && gp.evaluations.get() < budget {
            let mut improved = false;
            for &k in &coords {
                for dir in [1.0, -1.0] {
                    if gp.evaluations.get() >= budget {
                        break;
                    }
                    let (mut th, mut ll) = (point.theta.clone(), point.log_lambda);
                    match k {
                        0 => ll = (ll + dir * step).clamp(bounds.noise.0, bounds.noise.1),
                        1 => th
                            .iter_mut()
                            .zip(&gp.table.forms)
                            .for_each(|(t, f)| *t = (*t + dir * step / f.log_weight_slope()).clamp(lo_b, hi_b)),
                        a => th[a - 2] = (th[a - 2] + dir * step).clamp(lo_b, hi_b),
                    }
                    if th == point.theta && ll == point.log_lambda {
                        continue;
                    }
                    if let Some(v) = gp.eval(&th, ll) {
                        if v.0 > point.value.0 + 1e-9 * point.value.0.abs() {
                            *point = SearchPoint { value: v, theta: th, log_lambda: ll };
                            improved = true;
                            break; // keep moving along improving directions
                        }
                    }
                }
            }
            if !improved {
                step *= 0.5;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::KernelRidge;
    use super::*;
    use cbd_protocol::JointKernelAxis;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn normal(rng: &mut ChaCha8Rng) -> f64 {
        let u1: f64 = rng.gen_range(f64::EPSILON..1.0);
        let u2: f64 = rng.gen();
        (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()
    }

    /// Residuals drawn from the GP itself (b = 2, γ = 0.01, σ = 0.02) on a planar 2R arm.
    fn gp_sample(count: usize, seed: u64) -> (NominalModel, Measurements, Measurements) {
        let nominal = NominalModel::planar(&[1.0, 0.5]).unwrap();
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let total = count + 200;
        let joints: Vec<f64> = (0..total * 2).map(|_| rng.gen_range(0.0..std::f64::consts::TAU)).collect();
        let truth = JointKernel { gamma: 0.01, axes: heapless::Vec::from_slice(&[JointKernelAxis::Periodic { b: 2.0 }; 2]).unwrap() };
        let mut k = kernel_matrix(&truth, &joints, &joints, 2);
        for i in 0..total {
            k[(i, i)] += 1e-10;
        }
        let l = k.llt(Side::Lower).unwrap().L().to_owned();
        let z = Mat::from_fn(total, 2, |_, _| normal(&mut rng));
        let f = &l * &z;
        let (mut train, mut test) = (Measurements::new(2, 2), Measurements::new(2, 2));
        for i in 0..total {
            let q = &joints[2 * i..2 * i + 2];
            let p = forward_kinematics(&nominal, q).position;
            if i < count {
                train.push(q, &[p[0] + f[(i, 0)] + 0.02 * normal(&mut rng), p[1] + f[(i, 1)] + 0.02 * normal(&mut rng)]);
            } else {
                test.push(q, &[p[0] + f[(i, 0)], p[1] + f[(i, 1)]]);
            }
        }
        (nominal, train, test)
    }

    #[test]
    fn recovers_the_generating_hyperparameters() {
        let (nominal, train, test) = gp_sample(300, 11);
        let opts = SearchOptions { task_scale: Some(1.0), ..SearchOptions::default() };
        let h = choose_kernel_ridge_hyperparameters(&nominal, &train, &opts).unwrap();
        let bs: Vec<f64> = h
            .kernel
            .axes
            .iter()
            .map(|a| match a {
                JointKernelAxis::Periodic { b } => *b,
                _ => panic!(),
            })
            .collect();
        assert!(bs.iter().all(|&b| (1.0..4.0).contains(&b)), "b {bs:?} (true 2)");
        assert!((h.noise_sigma - 0.02).abs() < 0.005, "σ {} (true 0.02)", h.noise_sigma);
        assert!(h.kernel.gamma > 0.003 && h.kernel.gamma < 0.03, "γ {} (true 0.01)", h.kernel.gamma);
        // The optimum is at least as likely as the generating values.
        let residual =
            Mat::from_fn(train.len(), 2, |i, c| train.position(i)[c] - forward_kinematics(&nominal, train.joints(i)).position[c]);
        let truth = JointKernel { gamma: 0.01, axes: heapless::Vec::from_slice(&[JointKernelAxis::Periodic { b: 2.0 }; 2]).unwrap() };
        let mut k = kernel_matrix(&truth, &train.joints, &train.joints, 2);
        for i in 0..train.len() {
            k[(i, i)] += 0.02 * 0.02;
        }
        let at_truth = log_marginal_likelihood(&k, &residual).unwrap();
        assert!(h.log_marginal_likelihood >= at_truth - 1e-6, "{} < {at_truth}", h.log_marginal_likelihood);
        // And the regression with them predicts the noise-free test values better than noise level.
        let krr = KernelRidge::fit(&nominal, &train, h.kernel.clone(), h.ridge()).unwrap();
        let pred = krr.predict(&nominal, &test.joints);
        let rms = (pred.iter().zip(&test.positions).map(|(a, b)| (a - b).powi(2)).sum::<f64>() / test.len() as f64).sqrt();
        assert!(rms < 0.02, "test rms {rms}");
    }

    /// Above `max_points` rows the subset's choice is refined on every row in weight space: the
    /// kernel form's profiled likelihood on every row (an independent check) is at least the subset's
    /// choice's there, and equals what the refinement reports.
    #[test]
    fn refinement_on_every_row_keeps_or_improves_the_subsets_choice() {
        let (nominal, train, _) = gp_sample(900, 7);
        let opts = SearchOptions { task_scale: Some(1.0), max_points: 300, ..SearchOptions::default() };
        let subset =
            choose_kernel_ridge_hyperparameters(&nominal, &train, &SearchOptions { max_weight_space_weights: 0, ..opts.clone() }).unwrap();
        assert_eq!((subset.rows_used, subset.weight_space.is_none()), (300, true));
        assert!(subset.weight_space_declined.as_deref().is_some_and(|w| w.contains("limit 0")), "{:?}", subset.weight_space_declined);
        let refined = choose_kernel_ridge_hyperparameters(&nominal, &train, &opts).unwrap();
        let report = refined.weight_space.as_ref().expect("refined on every row");
        assert_eq!((refined.rows_used, report.kernel_rows, refined.evaluations), (900, 300, subset.evaluations));
        let residual = normalised_residual(&nominal, &train, 1.0);
        // Profiled on every row: (lml, γ̂) at a choice's widths and noise ratio σ²/γ.
        let every_row = |h: &Hyperparameters| {
            let unit = JointKernel { gamma: 1.0, ..h.kernel.clone() };
            profiled_lml(&kernel_matrix(&unit, &train.joints, &train.joints, 2), &residual, h.ridge() / h.kernel.gamma).unwrap()
        };
        let (before, after) = (every_row(&subset).0, every_row(&refined));
        // Up to the truncation (≤ 0.01 nats from the kernel form, tested in `weight_space`).
        assert!(after.0 >= before - 0.01, "every row: refined {} < the subset's choice {before}", after.0);
        assert!(
            (after.0 - refined.log_marginal_likelihood).abs() <= 0.01,
            "kernel form {} vs weight space {}",
            after.0,
            refined.log_marginal_likelihood
        );
        assert!((after.1 / refined.kernel.gamma).ln().abs() <= 0.02 / 1800.0, "γ̂ {} vs {}", after.1, refined.kernel.gamma);
        errln!(
            "every row: subset's choice {before:.3}, refined {:.3} ({} functions, {} evaluations)",
            after.0,
            report.weights,
            report.evaluations
        );
    }

    #[test]
    fn profiled_value_matches_the_full_likelihood() {
        let (nominal, train, _) = gp_sample(60, 5);
        let h = choose_kernel_ridge_hyperparameters(
            &nominal,
            &train,
            &SearchOptions { task_scale: Some(1.0), max_evaluations: 30, ..Default::default() },
        )
        .unwrap();
        let residual =
            Mat::from_fn(train.len(), 2, |i, c| train.position(i)[c] - forward_kinematics(&nominal, train.joints(i)).position[c]);
        let mut k = kernel_matrix(&h.kernel, &train.joints, &train.joints, 2);
        for i in 0..train.len() {
            k[(i, i)] += h.ridge();
        }
        let full = log_marginal_likelihood(&k, &residual).unwrap();
        assert!((full - h.log_marginal_likelihood).abs() < 1e-8 * full.abs().max(1.0), "{full} vs {}", h.log_marginal_likelihood);
        assert!(h.evaluations <= 7 * 7 + 1, "{}", h.evaluations);
    }
}

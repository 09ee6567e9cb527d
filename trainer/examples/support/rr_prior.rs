//! Shared by the issue-25 prior prototypes (`rr_joint_prior`, `rr_free_spectrum`): the linearised
//! model r = A w + e on a fixed basis with a prior variance per weight, its exact weight-space
//! evidence and gradient, and the two searches (Nelder–Mead, BFGS) the prototypes run on it.
#![allow(dead_code)]

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::llt::factor::{cholesky_in_place, cholesky_in_place_scratch};
use faer::linalg::matmul::matmul;
use faer::linalg::triangular_solve::{solve_lower_triangular_in_place, solve_upper_triangular_in_place};
use faer::{Accum, Mat, Par};

/// The noisy RR benchmark: the per_axis × per_axis grid of `cbd simulate` noise-free and with
/// σ = 1e-4 (`noise_seed`), and 3000 noise-free uniformly random test configurations (seed 7).
pub fn benchmark(
    per_axis: usize,
    noise_seed: u64,
) -> (cbd_trainer::data::Measurements, cbd_trainer::data::Measurements, cbd_trainer::data::Measurements) {
    use cbd_trainer::simulate::{add_noise, configurations, rr, Sampling};
    let real = rr::RealRr::default();
    let clean = real.measure(&configurations(Sampling::Grid { per_axis }, 2));
    let mut noisy = clean.clone();
    add_noise(&mut noisy.positions, 1e-4, noise_seed);
    let test = real.measure(&configurations(Sampling::Uniform { count: 3000, seed: 7 }, 2));
    (clean, noisy, test)
}

/// Plain CbD's choice (`cbd fit`'s evidence, printed) as the blob's kernels, with Euler × 1.
pub fn plain_cbd(
    nominal: &cbd_protocol::NominalModel,
    noisy: &cbd_trainer::data::Measurements,
    norm: &cbd_protocol::Normalisation,
) -> (cbd_trainer::evidence::Evidence, cbd_protocol::JointKernel, cbd_protocol::TaskKernel, cbd_protocol::Integrator) {
    let e = cbd_trainer::evidence::choose_cbd_hyperparameters(nominal, noisy, norm, &Default::default()).unwrap();
    let h = &e.hyperparameters;
    println!("plain cbd evidence {:.2} ({}), {:?}", e.log_evidence, e.form, h);
    let cbd_trainer::solver::FlowHyperparameters { joint_kernel: jk, task_kernel: tk, .. } = h.to_internal(norm);
    let integ = cbd_protocol::Integrator { method: cbd_protocol::IntegratorMethod::Euler, steps: 1 };
    (e, jk, tk, integ)
}

/// The measurements in normalised task units minus the nominal positions `nominal` (normalised,
/// row-major): the residual both fields fit.
pub fn residual(data: &cbd_trainer::data::Measurements, norm: &cbd_protocol::Normalisation, nominal: &[f64]) -> Vec<f64> {
    let m = data.task_dim;
    data.positions
        .chunks_exact(m)
        .flat_map(|y| (0..m).map(move |c| norm.position_to_internal(c, y[c])))
        .zip(nominal)
        .map(|(y, k)| y - k)
        .collect()
}

/// Mean Euclidean error of planar positions (x, y pairs).
pub fn mean_error(pred: &[f64], truth: &[f64]) -> f64 {
    let e: f64 = pred.chunks_exact(2).zip(truth.chunks_exact(2)).map(|(p, t)| ((p[0] - t[0]).powi(2) + (p[1] - t[1]).powi(2)).sqrt()).sum();
    e / (pred.len() / 2) as f64
}

/// r = A w + e, w ~ N(0, Λ), e ~ N(0, σ² I): A, r and G = AᵀA, s = Aᵀr, |r|².
pub struct LinearGaussian {
    pub a: Mat<f64>,
    pub residual: Vec<f64>,
    pub gram: Mat<f64>,
    pub s: Vec<f64>,
    pub rr: f64,
    pub obs: usize,
}

/// The evidence at one (Λ, σ): nlml = ½ (|e|²/σ² + |w̃|²) + ½ ln det B + N m ln σ (+ const), with
/// B = I + Λ^½ G Λ^½ / σ² = L Lᵀ, the posterior mean w = Λ^½ w̃, w̃ = B⁻¹ Λ^½ s / σ², and e = r − A w
/// (the same value as ½ (|r|²/σ² − |L⁻¹ Λ^½ s|²/σ⁴) + …, without that difference of two large terms,
/// whose rounding drowns a finite-difference check at N = 256); the effective degrees
/// of freedom tr(A Σ_w Aᵀ)/σ² = r − tr B⁻¹; and, if asked, the gradient
/// ∂ nlml / ∂ ln λ_k = ½ (1 − (B⁻¹)_kk − w̃_k²) (w̃ = Λ^{−½} w) and ∂ nlml / ∂ ln σ = N m − r + tr B⁻¹ − |e|²/σ².
pub struct Posterior {
    pub nlml: f64,
    pub weights: Vec<f64>,
    pub dof: f64,
    pub grad_log_variance: Vec<f64>,
    pub grad_log_sigma: f64,
}

impl LinearGaussian {
    pub fn new(a: &Mat<f64>, residual: &[f64]) -> LinearGaussian {
        let r = a.ncols();
        let mut gram = Mat::zeros(r, r);
        matmul(gram.as_mut(), Accum::Replace, a.transpose(), a.as_ref(), 1.0, Par::Seq);
        LinearGaussian {
            a: a.clone(),
            residual: residual.to_vec(),
            gram,
            s: project(a, residual),
            rr: residual.iter().map(|v| v * v).sum(),
            obs: residual.len(),
        }
    }

    /// The posterior at prior variances `lam` and ln σ; `s` replaces Aᵀr (e.g. the noise-free
    /// measurements' projection, for the bias) in the weights only; `None` if B is not positive definite.
    pub fn posterior(&self, lam: &[f64], log_sigma: f64, s: Option<&[f64]>, gradient: bool) -> Option<Posterior> {
        let r = self.gram.nrows();
        let sq: Vec<f64> = lam.iter().map(|v| v.sqrt()).collect();
        let sigma2 = (2.0 * log_sigma).exp();
        let mut b = Mat::from_fn(r, r, |i, j| sq[i] * self.gram[(i, j)] * sq[j] / sigma2 + if i == j { 1.0 } else { 0.0 });
        let par = Par::Seq;
        let mut mem = MemBuffer::new(cholesky_in_place_scratch::<f64>(r, par, Default::default()));
        cholesky_in_place(b.as_mut(), Default::default(), par, MemStack::new(&mut mem), Default::default()).ok()?;
        let logdet: f64 = (0..r).map(|i| 2.0 * b[(i, i)].ln()).sum();
        let solve = |s: &[f64]| -> Vec<f64> {
            let mut x = Mat::from_fn(r, 1, |i, _| sq[i] * s[i]);
            solve_lower_triangular_in_place(b.as_ref(), x.as_mut(), par);
            solve_upper_triangular_in_place(b.as_ref().transpose(), x.as_mut(), par);
            (0..r).map(|i| x[(i, 0)] / sigma2).collect()
        };
        let whitened = solve(&self.s);
        let weights_of = |w: &[f64]| -> Vec<f64> { w.iter().zip(&sq).map(|(w, s)| w * s).collect() };
        let fitted = weights_of(&whitened);
        let e2: f64 = (0..self.a.nrows())
            .map(|i| {
                let e = self.residual[i] - (0..r).map(|j| self.a[(i, j)] * fitted[j]).sum::<f64>();
                e * e
            })
            .sum();
        let w2: f64 = whitened.iter().map(|v| v * v).sum();
        let nlml = 0.5 * (e2 / sigma2 + w2) + 0.5 * logdet + self.obs as f64 * log_sigma;
        // (B⁻¹)_kk = column norms² of L⁻¹.
        let mut inv_l = Mat::<f64>::identity(r, r);
        solve_lower_triangular_in_place(b.as_ref(), inv_l.as_mut(), par);
        let diag: Vec<f64> = (0..r).map(|k| (0..r).map(|i| inv_l[(i, k)] * inv_l[(i, k)]).sum()).collect();
        let trace: f64 = diag.iter().sum();
        let weights = match s {
            Some(other) => weights_of(&solve(other)),
            None => fitted,
        };
        let (grad_log_variance, grad_log_sigma) = if gradient {
            let g = (0..r).map(|k| 0.5 * (1.0 - diag[k] - whitened[k] * whitened[k])).collect();
            (g, self.obs as f64 - r as f64 + trace - e2 / sigma2)
        } else {
            (Vec::new(), 0.0)
        };
        let nlml = nlml.is_finite().then_some(nlml)?;
        Some(Posterior { nlml, weights, dof: r as f64 - trace, grad_log_variance, grad_log_sigma })
    }
}

/// Aᵀ v.
pub fn project(a: &Mat<f64>, v: &[f64]) -> Vec<f64> {
    (0..a.ncols()).map(|j| (0..a.nrows()).map(|i| a[(i, j)] * v[i]).sum()).collect()
}

/// Nelder–Mead on `f` from `x0` over the coordinates marked `free`, initial steps `step`, restarted until no gain.
pub fn nelder_mead(f: &dyn Fn(&[f64]) -> f64, x0: &[f64], step: f64, free: &[bool]) -> (f64, Vec<f64>) {
    let idx: Vec<usize> = (0..x0.len()).filter(|&k| free[k]).collect();
    let k = idx.len();
    let embed = |y: &[f64]| {
        let mut x = x0.to_vec();
        for (j, &i) in idx.iter().enumerate() {
            x[i] = y[j];
        }
        x
    };
    let mut best_x: Vec<f64> = idx.iter().map(|&i| x0[i]).collect();
    let mut best_f = f(&embed(&best_x));
    for _restart in 0..3 {
        let mut simplex: Vec<(f64, Vec<f64>)> = vec![(best_f, best_x.clone())];
        for j in 0..k {
            let mut y = best_x.clone();
            y[j] += step;
            simplex.push((f(&embed(&y)), y));
        }
        for _ in 0..150 * k {
            simplex.sort_by(|a, b| a.0.total_cmp(&b.0));
            let centroid: Vec<f64> = (0..k).map(|j| simplex[..k].iter().map(|p| p.1[j]).sum::<f64>() / k as f64).collect();
            let worst = simplex[k].clone();
            let at = |a: f64| -> Vec<f64> { (0..k).map(|j| centroid[j] + a * (worst.1[j] - centroid[j])).collect() };
            let xr = at(-1.0);
            let fr = f(&embed(&xr));
            if fr < simplex[0].0 {
                let xe = at(-2.0);
                let fe = f(&embed(&xe));
                simplex[k] = if fe < fr { (fe, xe) } else { (fr, xr) };
            } else if fr < simplex[k - 1].0 {
                simplex[k] = (fr, xr);
            } else {
                let xc = at(0.5);
                let fc = f(&embed(&xc));
                if fc < worst.0 {
                    simplex[k] = (fc, xc);
                } else {
                    let x0 = simplex[0].1.clone();
                    for p in simplex.iter_mut().skip(1) {
                        p.1 = (0..k).map(|j| x0[j] + 0.5 * (p.1[j] - x0[j])).collect();
                        p.0 = f(&embed(&p.1));
                    }
                }
            }
            let spread = simplex.iter().map(|p| p.0).fold(f64::NEG_INFINITY, f64::max) - simplex[0].0;
            if spread < 1e-6 {
                break;
            }
        }
        simplex.sort_by(|a, b| a.0.total_cmp(&b.0));
        let gain = best_f - simplex[0].0;
        best_f = simplex[0].0;
        best_x = simplex[0].1.clone();
        if gain < 1e-4 {
            break;
        }
    }
    (best_f, embed(&best_x))
}

/// A criterion's value and gradient at θ; `None` where it is infeasible.
pub type ValueAndGradient<'a> = dyn Fn(&[f64]) -> Option<(f64, Vec<f64>)> + 'a;

/// BFGS with an Armijo backtracking line search on `f` (value, gradient; `None` = infeasible) from `x0`,
/// steps capped at 2 per coordinate; stops when a step gains under 1e-6 nats three times running, or
/// the gradient is below 1e-4 everywhere. Returns (value, x, iterations).
pub fn bfgs(f: &ValueAndGradient, x0: &[f64], max_iterations: usize) -> (f64, Vec<f64>, usize) {
    let k = x0.len();
    let mut x = x0.to_vec();
    let (mut fx, mut g) = f(&x).expect("BFGS start is infeasible");
    let mut h = Mat::<f64>::identity(k, k);
    let mut stalls = 0;
    let mut iterations = 0;
    while iterations < max_iterations {
        iterations += 1;
        if g.iter().all(|v| v.abs() < 1e-4) {
            break;
        }
        let mut d: Vec<f64> = (0..k).map(|i| -(0..k).map(|j| h[(i, j)] * g[j]).sum::<f64>()).collect();
        let mut slope: f64 = d.iter().zip(&g).map(|(a, b)| a * b).sum();
        if slope >= 0.0 {
            // Not a descent direction: restart from steepest descent.
            h = Mat::identity(k, k);
            d = g.iter().map(|v| -v).collect();
            slope = -g.iter().map(|v| v * v).sum::<f64>();
        }
        let cap = d.iter().fold(0.0f64, |a, v| a.max(v.abs()));
        let mut step = if cap > 2.0 { 2.0 / cap } else { 1.0 };
        let mut accepted = None;
        for _ in 0..40 {
            let trial: Vec<f64> = x.iter().zip(&d).map(|(x, d)| x + step * d).collect();
            if let Some((ft, gt)) = f(&trial) {
                if ft <= fx + 1e-4 * step * slope {
                    accepted = Some((trial, ft, gt));
                    break;
                }
            }
            step *= 0.3;
        }
        let Some((xn, fn_, gn)) = accepted else { break };
        let s: Vec<f64> = xn.iter().zip(&x).map(|(a, b)| a - b).collect();
        let y: Vec<f64> = gn.iter().zip(&g).map(|(a, b)| a - b).collect();
        let sy: f64 = s.iter().zip(&y).map(|(a, b)| a * b).sum();
        if sy > 1e-12 {
            // H ← (I − ρ s yᵀ) H (I − ρ y sᵀ) + ρ s sᵀ.
            let rho = 1.0 / sy;
            let hy: Vec<f64> = (0..k).map(|i| (0..k).map(|j| h[(i, j)] * y[j]).sum()).collect();
            let yhy: f64 = y.iter().zip(&hy).map(|(a, b)| a * b).sum();
            for i in 0..k {
                for j in 0..k {
                    h[(i, j)] += -rho * (hy[i] * s[j] + s[i] * hy[j]) + (rho * rho * yhy + rho) * s[i] * s[j];
                }
            }
        }
        stalls = if fx - fn_ < 1e-6 { stalls + 1 } else { 0 };
        x = xn;
        fx = fn_;
        g = gn;
        if stalls >= 3 {
            break;
        }
    }
    (fx, x, iterations)
}

//! Why kernel ridge closes the gap at large N (issue 25; docs/DESIGN.md §3, BENCHMARKS.md "Well-conditioned
//! models"): on the noisy RR benchmark (`cbd bench --evidence-sizes`' data: √N × √N grid, σ = 1e-4, noise
//! seed 0x5eee unless given; 3000 random noise-free test configurations, seed 7) each method's test error
//! split into bias and noise. Both predictors are linear in the measurements at fixed hyperparameters, so
//! the fit to the noise-free measurements is the bias and the difference of the two fits the noise part,
//! exactly. CbD is the Euler × 1 model in weight space (what the blob evaluates), kernel ridge the peer.
//!
//!     cargo run --release -p cbd-trainer --example rr_bias_noise -- PER_AXIS [NOISE_SEED|-] [MODE [B_FACTOR]]
//!
//! MODE: none (the split, and CbD's bias by joint angle), `scan` (CbD around its evidence θ: truncation,
//! b, a, γ), `dft` (the biases' largest harmonics e^{i(h1 q1 + h2 q2)} of r_x + i r_y on the training grid),
//! `oracle` (coordinate search of CbD's θ on the TEST error, from the evidence θ with b × B_FACTOR: what
//! the model family reaches at all — a diagnosis, never a selection rule).

use cbd_protocol::*;
use cbd_trainer::axis_forms::joint_series;
use cbd_trainer::baselines::kernel_ridge::{fit_kernel_ridge_peer, KernelRidge};
use cbd_trainer::data::Measurements;
use cbd_trainer::evidence::CbdHyperparameters;
use cbd_trainer::expansion::basis::{truncate, AxisSeries};
use cbd_trainer::expansion::solve::{apply, design, posterior_weights, prior_variances, LinearProblem};
use cbd_trainer::expansion::{task_radius_of, tolerance_for};
use cbd_trainer::flow::ControlPoints;
use cbd_trainer::simulate::{add_noise, configurations, rr, Sampling};

fn stats(pred: &[f64], truth: &[f64]) -> (f64, f64) {
    let e: Vec<f64> =
        pred.chunks_exact(2).zip(truth.chunks_exact(2)).map(|(p, t)| ((p[0] - t[0]).powi(2) + (p[1] - t[1]).powi(2)).sqrt()).collect();
    let mean = e.iter().sum::<f64>() / e.len() as f64;
    let rms = (e.iter().map(|v| v * v).sum::<f64>() / e.len() as f64).sqrt();
    (mean, rms)
}

struct Cbd {
    test_clean: Vec<f64>,
    test_noisy: Vec<f64>,
    weights: usize,
    largest: f64,
}

/// CbD's linear model (Euler × 1) in weight space at `h`, fitted to noisy and clean targets, predicted at `test`.
fn cbd_at(
    nominal: &NominalModel,
    noisy: &Measurements,
    clean: &Measurements,
    test: &[f64],
    h: &CbdHyperparameters,
    tol_factor: f64,
) -> Option<Cbd> {
    let norm = noisy.normalisation();
    let cbd_trainer::solver::FlowHyperparameters { joint_kernel: jk, task_kernel: tk, sigma, .. } = h.to_internal(&norm);
    let integ = Integrator { method: IntegratorMethod::Euler, steps: 1 };
    let cp = ControlPoints::new(nominal, &norm, noisy.joints.clone(), jk.clone(), tk, MomentumLaw::Hamiltonian, integ);
    let (m, n) = (2, 2);
    let nom = cp.nominal_positions();
    let jac = cp.nominal_jacobians();
    let mean_j2 = jac.iter().map(|v| v * v).sum::<f64>() / nom.len() as f64;
    let tolerance = (tolerance_for(sigma, 1.0 + jk.gamma * mean_j2) * tol_factor).max(1e-16);
    let ranges = vec![1.25 * std::f64::consts::PI; 2];
    let Some(joint) = joint_series(&jk, &ranges).and_then(|axes| truncate(&axes, tolerance)) else { return None };
    let Some(task) = truncate(&vec![AxisSeries::gaussian(task_radius_of(&nom, m) / tk.width); m], tolerance) else { return None };
    let variances = prior_variances(jk.gamma, n, m, &joint, &task);
    let tcp = ControlPoints::new(nominal, &norm, test.to_vec(), jk.clone(), tk, MomentumLaw::Hamiltonian, integ);
    let tnom = tcp.nominal_positions();
    let tjac = tcp.nominal_jacobians();
    let zero = vec![0.0; tnom.len()];
    let tproblem = LinearProblem { dims: tcp.dims, points: &tcp.points, nominal: &tnom, jacobians: &tjac, residual: &zero };
    let at = design(&tproblem, &jk, &tk, &joint, &task);
    let mut largest = 0.0f64;
    let mut fit = |data: &Measurements| -> Vec<f64> {
        let norm = &norm;
        let target: Vec<f64> =
            data.positions.chunks_exact(m).flat_map(|y| (0..m).map(move |c| norm.position_to_internal(c, y[c]))).collect();
        let residual: Vec<f64> = target.iter().zip(&nom).map(|(y, k)| y - k).collect();
        let problem = LinearProblem { dims: cp.dims, points: &cp.points, nominal: &nom, jacobians: &jac, residual: &residual };
        let a = design(&problem, &jk, &tk, &joint, &task);
        let w = posterior_weights(&a, &variances, sigma, &residual).unwrap();
        largest = largest.max(w.iter().zip(&variances).map(|(w, v)| w.abs() / v.sqrt()).fold(0.0, f64::max));
        let d = apply(&at, &w);
        tnom.iter().zip(&d).enumerate().map(|(i, (k, d))| norm.position_to_user(i % m, k + d)).collect()
    };
    let test_noisy = fit(noisy);
    let test_clean = fit(clean);
    Some(Cbd { test_clean, test_noisy, weights: variances.len(), largest })
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let per_axis: usize = args.get(1).map_or(64, |s| s.parse().unwrap());
    let noise_seed: u64 =
        args.get(2).map_or(1u64.wrapping_add(0x5eed), |s| if s == "-" { 1u64.wrapping_add(0x5eed) } else { s.parse().unwrap() });
    let real = rr::RealRr::default();
    let nominal = rr::nominal();
    let clean = real.measure(&configurations(Sampling::Grid { per_axis }, 2));
    let mut noisy = clean.clone();
    add_noise(&mut noisy.positions, 1e-4, noise_seed);
    let test = real.measure(&configurations(Sampling::Uniform { count: 3000, seed: 7 }, 2));
    let split = |name: &str, pn: &[f64], pc: &[f64]| {
        let (tm, tr) = stats(pn, &test.positions);
        let (bm, br) = stats(pc, &test.positions);
        let (nm, nr) = stats(pn, pc);
        println!(
            "{name}: test mean {tm:.4e} rms {tr:.4e} | bias (clean fit) mean {bm:.4e} rms {br:.4e} | noise part mean {nm:.4e} rms {nr:.4e}"
        );
    };
    // Kernel ridge with its own evidence (skipped with CBD_DIAG_NO_KRR set: its N × N Cholesky
    // dominates at N = 16384).
    let krr = std::env::var_os("CBD_DIAG_NO_KRR").is_none().then(|| {
        let peer = fit_kernel_ridge_peer(&nominal, &noisy, &Default::default()).unwrap();
        let hk = &peer.hyperparameters;
        println!(
            "krr: kernel {:?} sigma {:.4e} (data units {:.4e}), lml {:.2}, rows {}",
            hk.kernel,
            hk.noise_sigma,
            hk.noise_sigma * hk.task_scale,
            hk.log_marginal_likelihood,
            hk.rows_used
        );
        let pn = peer.regression.predict(&nominal, &test.joints);
        let kc = KernelRidge::fit(&nominal, &clean, hk.kernel.clone(), hk.ridge()).unwrap();
        let pc = kc.predict(&nominal, &test.joints);
        split("krr", &pn, &pc);
        (kc, pc)
    });
    // CbD with its own evidence.
    let t0 = std::time::Instant::now();
    let e = cbd_trainer::evidence::choose_cbd_hyperparameters(&nominal, &noisy, &noisy.normalisation(), &Default::default()).unwrap();
    println!(
        "cbd evidence {:.2} on {} rows ({}), {:.1} s: {:?}",
        e.log_evidence,
        e.rows_used,
        e.form,
        t0.elapsed().as_secs_f64(),
        e.hyperparameters
    );
    let h0 = e.hyperparameters.clone();
    let c = cbd_at(&nominal, &noisy, &clean, &test.joints, &h0, 1.0).unwrap();
    println!("cbd weights {} largest whitened {:.1}", c.weights, c.largest);
    split("cbd", &c.test_noisy, &c.test_clean);
    // Where the bias sits: by |sin q2| (the fold at q2 = 0, π) and by q1.
    let bins = |name: &str, pred: &[f64], key: &dyn Fn(&[f64]) -> usize, nb: usize| {
        let mut sum = vec![0.0; nb];
        let mut cnt = vec![0usize; nb];
        for ((q, p), t) in test.joints.chunks_exact(2).zip(pred.chunks_exact(2)).zip(test.positions.chunks_exact(2)) {
            let k = key(q).min(nb - 1);
            sum[k] += ((p[0] - t[0]).powi(2) + (p[1] - t[1]).powi(2)).sqrt();
            cnt[k] += 1;
        }
        let row: Vec<String> = sum.iter().zip(&cnt).map(|(s, c)| format!("{:.2e}({c})", s / *c as f64)).collect();
        println!("{name}: {}", row.join(" "));
    };
    let by_sin = |q: &[f64]| (q[1].sin().abs() * 5.0) as usize;
    let by_q1 = |q: &[f64]| ((q[0].rem_euclid(2.0 * std::f64::consts::PI)) / (2.0 * std::f64::consts::PI) * 8.0) as usize;
    bins("cbd bias by |sin q2| (5 bins)", &c.test_clean, &by_sin, 5);
    if let Some((_, pc)) = &krr {
        bins("krr bias by |sin q2| (5 bins)", pc, &by_sin, 5);
        bins("krr bias by q1 (8 bins)", pc, &by_q1, 8);
    }
    bins("cbd bias by q1 (8 bins)", &c.test_clean, &by_q1, 8);
    let by_q2 = |q: &[f64]| ((q[1].rem_euclid(2.0 * std::f64::consts::PI)) / (2.0 * std::f64::consts::PI) * 8.0) as usize;
    bins("cbd bias by q2 (8 bins)", &c.test_clean, &by_q2, 8);
    if args.get(3).map(|s| s == "dft").unwrap_or(false) {
        // The clean fit's residual on the training grid, Fourier coefficients of z = r_x + i r_y.
        let c = cbd_at(&nominal, &noisy, &clean, &clean.joints, &h0, 1.0).unwrap();
        let mut fits = vec![("cbd", c.test_clean.clone())];
        if let Some((kc, _)) = &krr {
            fits.push(("krr", kc.predict(&nominal, &clean.joints)));
        }
        for (name, pred) in &fits {
            let g = per_axis as i64;
            let res: Vec<(f64, f64)> =
                pred.chunks_exact(2).zip(clean.positions.chunks_exact(2)).map(|(p, t)| (p[0] - t[0], p[1] - t[1])).collect();
            let mut coef = Vec::new();
            for h1 in -6i64..=6 {
                for h2 in -6i64..=6 {
                    let (mut re, mut im) = (0.0, 0.0);
                    for (k, q) in clean.joints.chunks_exact(2).enumerate() {
                        let ph = -(h1 as f64 * q[0] + h2 as f64 * q[1]);
                        let (s, co) = ph.sin_cos();
                        re += res[k].0 * co - res[k].1 * s;
                        im += res[k].0 * s + res[k].1 * co;
                    }
                    let amp = (re * re + im * im).sqrt() / (g * g) as f64;
                    coef.push((amp, h1, h2));
                }
            }
            coef.sort_by(|a, b| b.0.total_cmp(&a.0));
            let top: Vec<String> = coef.iter().take(12).map(|(a, h1, h2)| format!("({h1},{h2}) {a:.2e}")).collect();
            println!("{name} bias on the grid, top harmonics of r_x + i r_y: {}", top.join(", "));
        }
    }
    if args.get(3).map(|s| s == "oracle").unwrap_or(false) {
        // Coordinate search on the test error (an oracle: what the family can reach at all).
        let get = |h: &CbdHyperparameters, k: usize| -> f64 {
            match k {
                0 | 1 => {
                    if let JointKernelAxis::Periodic { b } = h.joint_axes[k] {
                        b
                    } else {
                        0.0
                    }
                }
                2 => h.joint_gamma,
                3 => h.task_width,
                4 => h.task_gamma,
                _ => h.sigma,
            }
        };
        let set = |h: &mut CbdHyperparameters, k: usize, v: f64| match k {
            0 | 1 => h.joint_axes[k] = JointKernelAxis::Periodic { b: v },
            2 => h.joint_gamma = v,
            3 => h.task_width = v,
            4 => h.task_gamma = v,
            _ => h.sigma = v,
        };
        let score = |h: &CbdHyperparameters| {
            cbd_at(&nominal, &noisy, &clean, &test.joints, h, 1.0).map_or(f64::INFINITY, |c| stats(&c.test_noisy, &test.positions).0)
        };
        let mut best = h0.clone();
        let f0: f64 = args.get(4).map_or(1.0, |s| s.parse().unwrap());
        for a in best.joint_axes.iter_mut() {
            if let JointKernelAxis::Periodic { b } = a {
                *b *= f0;
            }
        }
        let mut best_s = score(&best);
        for step in [4.0f64, 2.0, 1.41, 1.19] {
            let mut improved = true;
            while improved {
                improved = false;
                for k in 0..6 {
                    for f in [step, 1.0 / step] {
                        let mut h = best.clone();
                        set(&mut h, k, get(&best, k) * f);
                        let s = score(&h);
                        if s < best_s {
                            best_s = s;
                            best = h;
                            improved = true;
                            println!("oracle step {step}: param {k} ×{f:.3} → {best_s:.4e}");
                        }
                    }
                }
            }
        }
        println!("oracle best {best_s:.4e} at {best:?}");
        let c = cbd_at(&nominal, &noisy, &clean, &test.joints, &best, 1.0).unwrap();
        split("cbd oracle", &c.test_noisy, &c.test_clean);
    }
    if args.get(3).map(|s| s == "scan").unwrap_or(false) {
        let set_b = |h: &mut CbdHyperparameters, f: f64| {
            for a in h.joint_axes.iter_mut() {
                if let JointKernelAxis::Periodic { b } = a {
                    *b *= f;
                }
            }
        };
        for &tf in &[1e-2] {
            let Some(c) = cbd_at(&nominal, &noisy, &clean, &test.joints, &h0, tf) else {
                println!("declined");
                continue;
            };
            split(&format!("cbd tol×{tf:e} ({} weights)", c.weights), &c.test_noisy, &c.test_clean);
        }
        for &f in &[3.0, 10.0, 30.0, 100.0, 300.0] {
            let mut h = h0.clone();
            set_b(&mut h, f);
            let Some(c) = cbd_at(&nominal, &noisy, &clean, &test.joints, &h, 1.0) else {
                println!("declined");
                continue;
            };
            split(&format!("cbd b×{f} ({} weights)", c.weights), &c.test_noisy, &c.test_clean);
        }
        for (axis, f) in [(0usize, 10.0), (1, 10.0), (0, 30.0), (1, 30.0)] {
            let mut h = h0.clone();
            if let JointKernelAxis::Periodic { b } = &mut h.joint_axes[axis] {
                *b *= f;
            }
            let Some(c) = cbd_at(&nominal, &noisy, &clean, &test.joints, &h, 1.0) else { continue };
            split(&format!("cbd b{}×{f} ({} weights)", axis + 1, c.weights), &c.test_noisy, &c.test_clean);
        }
        for &f in &[0.5, 0.25, 0.1] {
            let mut h = h0.clone();
            h.task_width *= f;
            let Some(c) = cbd_at(&nominal, &noisy, &clean, &test.joints, &h, 1.0) else {
                println!("declined");
                continue;
            };
            split(&format!("cbd a×{f} ({} weights)", c.weights), &c.test_noisy, &c.test_clean);
        }
        for &f in &[0.1, 10.0] {
            let mut h = h0.clone();
            h.joint_gamma *= f;
            let Some(c) = cbd_at(&nominal, &noisy, &clean, &test.joints, &h, 1.0) else {
                println!("declined");
                continue;
            };
            split(&format!("cbd γV×{f} ({} weights)", c.weights), &c.test_noisy, &c.test_clean);
            let mut h = h0.clone();
            h.task_gamma *= f;
            let Some(c) = cbd_at(&nominal, &noisy, &clean, &test.joints, &h, 1.0) else {
                println!("declined");
                continue;
            };
            split(&format!("cbd γW×{f} ({} weights)", c.weights), &c.test_noisy, &c.test_clean);
        }
    }
}

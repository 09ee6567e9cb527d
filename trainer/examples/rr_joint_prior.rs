//! Issue 25 prototype: other joint priors for CbD on the noisy RR benchmark (the data of
//! `rr_bias_noise`: √N × √N grid, σ = 1e-4, noise seed 0x5eee; 3000 random noise-free test
//! configurations, seed 7), each with hyperparameters chosen by its OWN weight-space evidence on
//! every row, against plain CbD's evidence choice and kernel ridge with its own evidence.
//!
//!     cargo run --release -p cbd-trainer --example rr_joint_prior -- PER_AXIS [B_BOX [q|u|uu [A_FACTOR]]]
//!
//! Joint prior (on one fixed basis of joint harmonics, those of exp(b_box (cos Δ − 1)) per axis; the
//! task basis at plain CbD's a × A_FACTOR): λ_f = γ₁ Π_d ω_{h_d}(b_d) + γ₂ Π_d ω_{h_d}(c_d), a flat
//! plus a narrower periodic kernel summed (γ₂ → 0 is plain CbD); the kernel in the joint angles (q) or
//! in the absolute link angles u = (q1, q1 + q2) (u: the field's components stay in q; uu: they are in
//! u too, V_q = A⁻¹ V_u with V_u's components independent, so the design takes J_q A⁻¹ = J_u).
//! The search (Nelder–Mead on ln θ) starts from plain CbD's own evidence choice (`cbd fit`'s).
//! nlml = ½ (|e|²/σ² + |w̃|²) + ½ ln det B + N m ln σ + const, B = I + Λ^½ AᵀA Λ^½ / σ² (support/rr_prior.rs).
//!
//! Measured (B_BOX 0.2; kernel ridge with its evidence: 6.2414e-5 at N = 256, 1.6810e-5 at 4096):
//! N = 4096, log evidence / test mean: q one kernel (`cbd fit`'s) 63362.85 / 1.4852e-5 (0.884×), q sum
//! 63364.19 / 1.5154e-5 (0.902×); u 63242.44 / 1.3454e-5 (0.800×), u with a × 1.83 63254.67 /
//! 1.3239e-5, uu 63258.71 / 1.3543e-5. N = 256: q 3570.46 / 4.9467e-5 (0.793×), u (a × 1.84) 3471.40 /
//! 5.0666e-5, uu 3461.75 / 4.8881e-5. Link angles lower the bias (5.4e-6 → 0.8e-6 at 4096) but lose
//! the evidence by 100–120 nats at both sizes, so an evidence choice between q and u keeps q; the sum
//! kernel's narrow part gets no weight (in q its optimum at c = b_box loses 127 nats at N = 256, 276 at 4096).
//! Since the evaluation moved to support/rr_prior.rs (shared with `rr_free_spectrum`; the value now as
//! ½ (|e|²/σ² + |w̃|²) + …, no difference of two large terms) plain CbD's θ at N = 256 prints 3569.85 /
//! 4.9467e-5 on this basis (the library's kernel form: 3570.46); the other figures were not re-run.

#[path = "support/rr_prior.rs"]
mod rr_prior;

use cbd_protocol::*;
use cbd_trainer::axis_forms::weights::periodic_weights;
use cbd_trainer::baselines::kernel_ridge::fit_kernel_ridge_peer;
use cbd_trainer::expansion::basis::{truncate, AxisSeries};
use cbd_trainer::expansion::solve::{apply, design, LinearProblem};
use cbd_trainer::expansion::{task_radius_of, tolerance_for};
use cbd_trainer::flow::ControlPoints;
use cbd_trainer::simulate::rr;
use rr_prior::{mean_error, nelder_mead, project, LinearGaussian};

/// The linear model r = A w + e on a fixed basis; θ = ln(γ_W, γ₁, b₁, b₂, γ₂, c₁, c₂, σ), normalised units.
struct Model {
    joint_orders: Vec<[usize; 2]>,
    task_functions: usize,
    linear: LinearGaussian,
    b_box: f64,
}

impl Model {
    fn variances(&self, t: &[f64]) -> Vec<f64> {
        let e: Vec<f64> = t.iter().map(|v| v.exp()).collect();
        let max_h = self.joint_orders.iter().flat_map(|o| o.iter().copied()).max().unwrap_or(0);
        let w = |b: f64| periodic_weights(b, max_h);
        let (b1, b2, c1, c2) = (w(e[2]), w(e[3]), w(e[5]), w(e[6]));
        let mut v = Vec::with_capacity(self.linear.gram.nrows());
        for o in &self.joint_orders {
            let lam = e[0] * (e[1] * b1[o[0]] * b2[o[1]] + e[4] * c1[o[0]] * c2[o[1]]);
            v.push(lam);
            v.push(lam);
        }
        v.extend(std::iter::repeat_n(e[0], self.task_functions * 2));
        v
    }

    /// (nlml, posterior mean weights w = Λ^½ B⁻¹ Λ^½ s / σ²) at θ, for the residual whose Aᵀ r is `clean_s` if given.
    fn evaluate(&self, t: &[f64], clean_s: Option<&[f64]>) -> Option<(f64, Vec<f64>)> {
        if t[2..4].iter().chain(&t[5..7]).any(|lb| lb.exp() > self.b_box) || t.iter().any(|v| !v.is_finite() || v.abs() > 60.0) {
            return None;
        }
        let post = self.linear.posterior(&self.variances(t), t[7], clean_s, false)?;
        Some((post.nlml, post.weights))
    }
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let per_axis: usize = args.get(1).map_or(16, |s| s.parse().unwrap());
    let b_box: f64 = args.get(2).map_or(0.5, |s| s.parse().unwrap());
    let (m, n) = (2usize, 2usize);
    let nominal = rr::nominal();
    let (clean, noisy, test) = rr_prior::benchmark(per_axis, 1u64.wrapping_add(0x5eed));
    if std::env::var_os("CBD_DIAG_NO_KRR").is_none() {
        let peer = fit_kernel_ridge_peer(&nominal, &noisy, &Default::default()).unwrap();
        let pn = peer.regression.predict(&nominal, &test.joints);
        println!("krr: test mean {:.4e} (lml {:.2})", mean_error(&pn, &test.positions), peer.hyperparameters.log_marginal_likelihood);
    }
    let norm = noisy.normalisation();
    let (e, jk, tk, integ) = rr_prior::plain_cbd(&nominal, &noisy, &norm);
    let h = &e.hyperparameters;
    let link_angles = args.get(3).is_some_and(|s| s == "u" || s == "uu");
    let components_in_u = args.get(3).is_some_and(|s| s == "uu");
    // J_u = J_q A⁻¹: column 1 − column 2, column 2 (m × n row-major blocks).
    let to_u = |jac: &mut Vec<f64>| {
        if components_in_u {
            for row in jac.chunks_exact_mut(n) {
                row[0] -= row[1];
            }
        }
    };
    let a_factor: f64 = args.get(4).map_or(1.0, |s| s.parse().unwrap());
    // u = A q, A unit lower-triangular of ones (one group of parallel axes).
    let map = |cp: &mut ControlPoints| {
        if link_angles {
            for q in cp.points.chunks_exact_mut(n) {
                q[1] += q[0];
            }
        }
    };
    let tk = TaskKernel { width: tk.width * a_factor };
    println!(
        "joint kernel coordinates: {}, task width × {a_factor}",
        match (link_angles, components_in_u) {
            (false, _) => "joint angles q",
            (true, false) => "link angles u, components in q",
            (true, true) => "link angles u, components in u",
        }
    );
    let mut cp = ControlPoints::new(&nominal, &norm, noisy.joints.clone(), jk.clone(), tk, MomentumLaw::Hamiltonian, integ);
    let nom = cp.nominal_positions();
    let mut jac = cp.nominal_jacobians();
    to_u(&mut jac);
    map(&mut cp);
    let mut tcp = ControlPoints::new(&nominal, &norm, test.joints.clone(), jk.clone(), tk, MomentumLaw::Hamiltonian, integ);
    let tnom = tcp.nominal_positions();
    let mut tjac = tcp.nominal_jacobians();
    to_u(&mut tjac);
    map(&mut tcp);
    // Bases: joint harmonics of the box's narrowest kernel (b_box per axis), task at plain CbD's a × A_FACTOR.
    let sigma_n = h.to_internal(&norm).sigma;
    let mean_j2 = jac.iter().map(|v| v * v).sum::<f64>() / nom.len() as f64;
    let tolerance = tolerance_for(sigma_n / 3.0, 1.0 + jk.gamma * mean_j2).max(1e-16);
    let joint = truncate(&vec![AxisSeries::periodic(b_box); n], tolerance).expect("joint basis");
    let task = truncate(&vec![AxisSeries::gaussian(task_radius_of(&nom, m) / tk.width); m], tolerance).expect("task basis");
    let joint_orders: Vec<[usize; 2]> = joint.codes.chunks_exact(n).map(|c| [(c[0] >> 1) as usize, (c[1] >> 1) as usize]).collect();
    let (res, res_clean) = (rr_prior::residual(&noisy, &norm, &nom), rr_prior::residual(&clean, &norm, &nom));
    let problem = LinearProblem { dims: cp.dims, points: &cp.points, nominal: &nom, jacobians: &jac, residual: &res };
    let a = design(&problem, &jk, &tk, &joint, &task);
    let zero = vec![0.0; tnom.len()];
    let tproblem = LinearProblem { dims: tcp.dims, points: &tcp.points, nominal: &tnom, jacobians: &tjac, residual: &zero };
    let at = design(&tproblem, &jk, &tk, &joint, &task);
    let r = a.ncols();
    let s_clean = project(&a, &res_clean);
    println!(
        "basis: {} joint functions × {n} + {} task functions × {m} = {r} weights (tolerance {tolerance:.1e}, b_box {b_box})",
        joint.len(),
        task.len()
    );
    let model = Model { joint_orders, task_functions: task.len(), linear: LinearGaussian::new(&a, &res), b_box };
    let predict = |w: &[f64]| -> Vec<f64> {
        let d = apply(&at, w);
        tnom.iter().zip(&d).enumerate().map(|(i, (k, d))| norm.position_to_user(i % m, k + d)).collect()
    };
    // Data units: ln p(y) = −nlml − N m ln scale − ½ N m ln 2π.
    let to_lml = |nlml: f64| -nlml - model.linear.obs as f64 * (norm.task_scale.ln() + 0.5 * (2.0 * std::f64::consts::PI).ln());
    let report = |name: &str, t: &[f64], nlml: f64| {
        let (_, w) = model.evaluate(t, None).unwrap();
        let (_, wc) = model.evaluate(t, Some(&s_clean)).unwrap();
        let (pn, pc) = (predict(&w), predict(&wc));
        let e: Vec<f64> = t.iter().map(|v| v.exp()).collect();
        println!(
            "{name}: lml {:.2} test mean {:.4e} bias {:.4e} | γW {:.3e} γ1 {:.3e} b ({:.2e}, {:.2e}) γ2 {:.3e} c ({:.2e}, {:.2e}) σ {:.3e}",
            to_lml(nlml),
            mean_error(&pn, &test.positions),
            mean_error(&pc, &test.positions),
            e[0],
            e[1],
            e[2],
            e[3],
            e[4],
            e[5],
            e[6],
            norm.length_to_user(e[7])
        );
    };
    let b_of = |k: usize| if let JointKernelAxis::Periodic { b } = jk.axes[k] { b } else { 1.0 };
    let gw = norm.variance_to_internal(h.task_gamma);
    let t_plain = vec![
        gw.ln(),
        jk.gamma.ln(),
        b_of(0).ln(),
        b_of(1).ln(),
        -50.0,
        b_box.ln() - 1.0,
        b_box.ln() - 1.0,
        norm.length_to_internal(h.sigma).ln(),
    ];
    let f = |t: &[f64]| model.evaluate(t, None).map_or(f64::INFINITY, |v| v.0);
    report("plain CbD's θ (its own evidence) on this basis", &t_plain, f(&t_plain));
    let single_free = [true, true, true, true, false, false, false, true];
    let (v, t1) = nelder_mead(&f, &t_plain, 0.5, &single_free);
    report("one kernel, searched on this basis", &t1, v);
    let all = [true; 8];
    let mut best = (v, t1.clone());
    for (lg2, lc) in [(-6.0, -1.0), (-6.0, -3.0), (-8.0, 0.0)] {
        let mut t = t1.clone();
        t[4] = t1[1] + lg2;
        t[5] = b_box.ln() + lc;
        t[6] = b_box.ln() + lc;
        let (v, t) = nelder_mead(&f, &t, 0.7, &all);
        report(&format!("sum, start γ2 = γ1 e^{lg2}, c = b_box e^{lc}"), &t, v);
        if v < best.0 {
            best = (v, t);
        }
    }
    report("sum, best evidence", &best.1, best.0);
}

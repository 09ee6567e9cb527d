//! The multi-step flow in weight space (docs/DESIGN.md §11, issue 25 item 4): every stage of the
//! fixed-step scheme has its own fields, v_s = Σ_f φ_f c_f^s and w_s = Σ_g ψ_g d_g^s (the
//! time-dependent velocity fields of LDDMM), with the energy of the discretised path,
//! Σ_s q_s (|c^s|²_Λ + |d^s|²_Λ) (q_s the scheme's quadrature weight of stage s: h for Euler, h/2
//! for Heun's two stages, h (1, 2, 2, 1)/6 for RK4's), plus the data term |k1(x_i) − y_i|²/σ².
//! In whitened weights z_s = √q_s Λ^{−1/2} θ_s the prior is |z|², so Gauss–Newton's matrix is
//! [J/σ; I]: well conditioned whatever the kernels, unlike the momenta, which cancel. Euler × 1 is
//! the linear model of `solve`; every scheme starts from its weights on every stage (the same path
//! to first order) and Levenberg–Marquardt refines it.
//!
//! Each training point's query ODE (eq. 20: dk = w_s(k) − J v_s(x), dJ = Dw_s J − J Dv_s) is
//! integrated with its forward-mode tangent with respect to every weight, by the runtime's own
//! integrator; points are independent, so they run in parallel.

use super::basis::Basis;
use super::solve::{prior_variances, task_exponents};
use crate::numeric::least_squares::QrLeastSquares;
use crate::numeric::levenberg_marquardt as lm;
use crate::numeric::FIXED_SPLIT;
use cbd_protocol::{Integrator, IntegratorMethod, JointKernel, TaskKernel, MAX_TASK_DIM as MT};
use cbd_runtime::internals::expansion::{for_each_task_basis, joint_row_len, write_joint_basis};
use cbd_runtime::internals::flow::Dims;
use faer::Mat;
use rayon::prelude::*;

/// The fixed part of the problem: data, bases, prior scales, scheme.
pub struct StageProblem<'a> {
    pub dims: Dims,
    pub points: &'a [f64],
    /// N × (m + m n): k0 and Dk0 at each point, internal units.
    pub initial: Vec<f64>,
    pub target: &'a [f64],
    pub joint_kernel: &'a JointKernel,
    pub task_kernel: &'a TaskKernel,
    pub joint: &'a Basis,
    pub task: &'a Basis,
    pub sigma: f64,
    pub integrator: Integrator,
    /// Prior variance of each weight of one stage (the protocol's layout).
    variances: Vec<f64>,
    /// θ_p = z_p · whitening[p] for every weight of every stage: √(λ_p / q_s).
    whitening: Vec<f64>,
    exponents: Vec<u8>,
}

/// The quadrature weight of each stage: how much of ∫ |v_t|² dt its field stands for.
pub fn quadrature(integrator: Integrator) -> Vec<f64> {
    let h = 1.0 / integrator.steps as f64;
    let per_step: &[f64] = match integrator.method {
        IntegratorMethod::Euler => &[1.0],
        IntegratorMethod::Heun => &[0.5, 0.5],
        IntegratorMethod::Rk4 => &[1.0 / 6.0, 1.0 / 3.0, 1.0 / 3.0, 1.0 / 6.0],
    };
    (0..integrator.steps).flat_map(|_| per_step.iter().map(move |b| b * h)).collect()
}

impl<'a> StageProblem<'a> {
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        dims: Dims,
        points: &'a [f64],
        initial: Vec<f64>,
        target: &'a [f64],
        joint_kernel: &'a JointKernel,
        task_kernel: &'a TaskKernel,
        joint: &'a Basis,
        task: &'a Basis,
        sigma: f64,
        integrator: Integrator,
    ) -> Self {
        let variances = prior_variances(joint_kernel.gamma, dims.n, dims.m, joint, task);
        let exponents = task_exponents(task);
        let whitening = quadrature(integrator).iter().flat_map(|q| variances.iter().map(move |v| (v / q).sqrt())).collect();
        StageProblem {
            dims,
            points,
            initial,
            target,
            joint_kernel,
            task_kernel,
            joint,
            task,
            sigma,
            integrator,
            variances,
            whitening,
            exponents,
        }
    }

    /// Weights of one stage.
    pub fn stage_len(&self) -> usize {
        self.variances.len()
    }

    /// θ (all stages, the protocol's layout) from whitened z.
    pub fn weights_of(&self, z: &[f64]) -> Vec<f64> {
        z.iter().zip(&self.whitening).map(|(zk, s)| zk * s).collect()
    }

    /// Whitened z with the same weights θ on every stage.
    pub fn uniform_start(&self, one_stage: &[f64]) -> Vec<f64> {
        quadrature(self.integrator)
            .iter()
            .flat_map(|q| one_stage.iter().zip(&self.variances).map(move |(t, v)| t * (q / v).sqrt()))
            .collect()
    }

    /// Whitened z with the linear model's weights on the first stage alone, divided by its quadrature
    /// weight, and zero fields after it: then k1 is exactly the linear model's (the later stages
    /// move nothing), the data term is the linear fit's and the prior's is 1/q_0 times its.
    pub fn first_stage_start(&self, one_stage: &[f64]) -> Vec<f64> {
        let q0 = quadrature(self.integrator).first().copied().unwrap_or(1.0);
        let mut z = vec![0.0; one_stage.len() * self.integrator.stage_count()];
        for ((zk, t), v) in z.iter_mut().zip(one_stage).zip(&self.variances) {
            *zk = t / q0 * (q0 / v).sqrt();
        }
        z
    }

    /// k1 at every point (N × m) and, with `tangent`, ∂k1/∂z (N m × P), for whitened weights z.
    pub fn evaluate(&self, z: &[f64], tangent: bool) -> Option<(Vec<f64>, Option<Mat<f64>>)> {
        let (m, n) = (self.dims.m, self.dims.n);
        let theta = self.weights_of(z);
        let params = if tangent { z.len() } else { 0 };
        let count = self.points.len() / n;
        let per_point: Vec<Option<(Vec<f64>, Vec<f64>)>> =
            (0..count).into_par_iter().map(|i| self.integrate_point(i, &theta, &self.whitening, params)).collect();
        let mut positions = Vec::with_capacity(count * m);
        let mut jac = tangent.then(|| Mat::zeros(count * m, params));
        for (i, r) in per_point.into_iter().enumerate() {
            let (k, dk) = r?;
            positions.extend_from_slice(&k);
            if let Some(jac) = jac.as_mut() {
                for p in 0..params {
                    for c in 0..m {
                        jac[(i * m + c, p)] = dk[p * m + c];
                    }
                }
            }
        }
        Some((positions, jac))
    }

    /// One point's query ODE with the tangents of all `params` weights: returns k1 (m) and
    /// ∂k1/∂z_p (params × m).
    fn integrate_point(&self, i: usize, theta: &[f64], scale: &[f64], params: usize) -> Option<(Vec<f64>, Vec<f64>)> {
        let (m, n) = (self.dims.m, self.dims.n);
        let ql = m + m * n;
        let x = &self.points[i * n..(i + 1) * n];
        let (r_v, w) = (self.joint.len(), self.stage_len());
        let row_len = joint_row_len(n);
        let mut rows = vec![0.0; r_v * row_len];
        write_joint_basis(self.joint_kernel, &self.joint.codes, n, x, &mut rows, false);
        let mut y = vec![0.0; ql * (1 + params)];
        y[..ql].copy_from_slice(&self.initial[i * ql..(i + 1) * ql]);
        let mut scratch = vec![0.0; cbd_runtime::internals::integrate::scratch_len(y.len())];
        let mut task_rows = vec![0.0; self.task.len() * (1 + m + m * m)];
        cbd_runtime::internals::integrate::integrate(
            self.integrator.method,
            self.integrator.steps,
            &mut y,
            &mut scratch,
            |stage, s, out| {
                let weights = &theta[stage * w..(stage + 1) * w];
                self.rates(stage, weights, scale, &rows, &mut task_rows, s, out, params);
                Ok::<(), ()>(())
            },
        )
        .ok()?;
        let finite = y.iter().all(|v| v.is_finite());
        let k1 = y[..m].to_vec();
        let dk: Vec<f64> = (0..params).flat_map(|p| y[ql * (1 + p)..ql * (1 + p) + m].to_vec()).collect();
        finite.then_some((k1, dk))
    }

    /// The primal rates and every tangent's (see the module doc) at stage `stage`.
    #[allow(clippy::too_many_arguments)]
    fn rates(
        &self,
        stage: usize,
        weights: &[f64],
        scale: &[f64],
        rows: &[f64],
        task_rows: &mut [f64],
        s: &[f64],
        out: &mut [f64],
        params: usize,
    ) {
        let (m, n) = (self.dims.m, self.dims.n);
        let ql = m + m * n;
        let r_v = self.joint.len();
        let row_len = joint_row_len(n);
        let (k, jac) = (&s[..m], &s[m..ql]);
        // v, Dv from the joint rows; w, Dw, D²w from the task basis at k.
        let (mut v, mut dv) = ([0.0; 8], [[0.0; 8]; 8]);
        for f in 0..r_v {
            let row = &rows[f * row_len..(f + 1) * row_len];
            for e in 0..n {
                let c = weights[f * n + e];
                v[e] += c * row[0];
                for d in 0..n {
                    dv[e][d] += c * row[1 + d];
                }
            }
        }
        let mut yk = [0.0; MT];
        yk[..m].copy_from_slice(k);
        let (mut wv, mut dw, mut d2w) = ([0.0; MT], [[0.0; MT]; MT], [[[0.0; MT]; MT]; MT]);
        let task_weights = &weights[r_v * n..];
        for_each_task_basis(self.task_kernel, &self.exponents, m, &yk[..m], true, |g, psi, grad, hess| {
            let tr = &mut task_rows[g * (1 + m + m * m)..(g + 1) * (1 + m + m * m)];
            tr[0] = psi;
            for b in 0..m {
                tr[1 + b] = grad[b];
                for c in 0..m {
                    tr[1 + m + b * m + c] = hess[b][c];
                }
            }
            for a in 0..m {
                let d = task_weights[g * m + a];
                wv[a] += d * psi;
                for b in 0..m {
                    dw[a][b] += d * grad[b];
                    for c in 0..m {
                        d2w[a][b][c] += d * hess[b][c];
                    }
                }
            }
        });
        let j = |a: usize, e: usize| jac[a * n + e];
        // Primal: dk = w − J v, dJ = Dw J − J Dv.
        for a in 0..m {
            out[a] = wv[a] - (0..n).map(|e| j(a, e) * v[e]).sum::<f64>();
            for d in 0..n {
                out[m + a * n + d] = (0..m).map(|b| dw[a][b] * j(b, d)).sum::<f64>() - (0..n).map(|e| j(a, e) * dv[e][d]).sum::<f64>();
            }
        }
        let w_len = self.stage_len();
        for p in 0..params {
            let (t, o) = (&s[ql * (1 + p)..ql * (2 + p)], &mut out[ql * (1 + p)..ql * (2 + p)]);
            let (tk, tj) = (&t[..m], &t[m..]);
            // δk' = Dw δk − δJ v;  δJ' = (D²w δk) J + Dw δJ − δJ Dv.
            for a in 0..m {
                o[a] = (0..m).map(|b| dw[a][b] * tk[b]).sum::<f64>() - (0..n).map(|e| tj[a * n + e] * v[e]).sum::<f64>();
                for d in 0..n {
                    let mut r = 0.0;
                    for b in 0..m {
                        let d2 = (0..m).map(|c| d2w[a][b][c] * tk[c]).sum::<f64>();
                        r += d2 * j(b, d) + dw[a][b] * tj[b * n + d];
                    }
                    r -= (0..n).map(|e| tj[a * n + e] * dv[e][d]).sum::<f64>();
                    o[m + a * n + d] = r;
                }
            }
            // The stage's own weights: ∂(w − J v) and ∂(Dw J − J Dv) with respect to z_p.
            if p / w_len != stage {
                continue;
            }
            let local = p % w_len;
            let kappa = scale[p];
            if local < r_v * n {
                let (f, e) = (local / n, local % n);
                let row = &rows[f * row_len..(f + 1) * row_len];
                for a in 0..m {
                    o[a] -= j(a, e) * kappa * row[0];
                    for d in 0..n {
                        o[m + a * n + d] -= j(a, e) * kappa * row[1 + d];
                    }
                }
            } else {
                let (g, c) = ((local - r_v * n) / m, (local - r_v * n) % m);
                let tr = &task_rows[g * (1 + m + m * m)..(g + 1) * (1 + m + m * m)];
                o[c] += kappa * tr[0];
                for d in 0..n {
                    o[m + c * n + d] += kappa * (0..m).map(|b| tr[1 + b] * j(b, d)).sum::<f64>();
                }
            }
        }
    }
}

impl StageProblem<'_> {
    /// ½ |k1(z) − y|²/σ² + ½ |z|², or `None` when the flow overflows.
    pub fn energy(&self, z: &[f64]) -> Option<f64> {
        let (k, _) = self.evaluate(z, false)?;
        Some(energy_of(self, &k, z))
    }
}

fn energy_of(problem: &StageProblem<'_>, k: &[f64], z: &[f64]) -> f64 {
    let sigma = problem.sigma;
    let data: f64 = k.iter().zip(problem.target).map(|(a, b)| (a - b) * (a - b)).sum::<f64>() / (sigma * sigma);
    0.5 * (data + z.iter().map(|v| v * v).sum::<f64>())
}

/// The fit as the least-squares driver sees it: a point is k1 (N × m), ∂k1/∂z and the energy.
struct WeightSteps<'p, 'a> {
    problem: &'p StageProblem<'a>,
    relative_tolerance: f64,
    prediction_tolerance: f64,
}

impl lm::Problem for WeightSteps<'_, '_> {
    type Eval = (Vec<f64>, Option<Mat<f64>>, f64);
    /// No Jacobian at the current point.
    type Error = ();

    fn cost(&self, at: &Self::Eval) -> f64 {
        at.2
    }

    /// [J/σ; I; √μ I] δ = −[(k − y)/σ; z; 0].
    fn propose(&mut self, z: &[f64], at: &Self::Eval, damping: f64, _iteration: usize) -> Result<Option<lm::Step>, ()> {
        let (k, sigma) = (&at.0, self.problem.sigma);
        let j = at.1.as_ref().ok_or(())?;
        let (rows, params) = (k.len(), z.len());
        let extra = if damping > 0.0 { params } else { 0 };
        let a = Mat::from_fn(rows + params + extra, params, |r, c| {
            if r < rows {
                j[(r, c)] / sigma
            } else if r - rows == c && r < rows + params {
                1.0
            } else if r >= rows + params && r - rows - params == c {
                damping.sqrt()
            } else {
                0.0
            }
        });
        let mut rhs: Vec<f64> = k.iter().zip(self.problem.target).map(|(a, b)| -(a - b) / sigma).collect();
        rhs.extend(z.iter().map(|v| -v));
        rhs.resize(rows + params + extra, 0.0);
        let delta = QrLeastSquares::factor(a, FIXED_SPLIT).solve(&rhs);
        Ok(Some(lm::Step { delta, predicted: None }))
    }

    fn evaluate(&mut self, trial: &[f64], _delta: &[f64]) -> Result<Option<Self::Eval>, ()> {
        Ok(self.problem.evaluate(trial, true).map(|(k, jac)| {
            let e = energy_of(self.problem, &k, trial);
            (k, jac, e)
        }))
    }

    fn accepted(&mut self, step: lm::Accepted<'_, Self::Eval>) -> Option<String> {
        let (k, kt, e) = (&step.from.0, &step.to.0, step.from.2);
        let moved = kt.iter().zip(k).fold(0.0f64, |s, (a, b)| s.max((a - b).abs()));
        // Or when the predictions move by less than 5 % of the training residual they leave:
        // the path's energy still falls, but the data no longer see it.
        let rms = (kt.iter().zip(self.problem.target).map(|(a, b)| (a - b) * (a - b)).sum::<f64>() / kt.len().max(1) as f64).sqrt();
        if step.decrease <= self.relative_tolerance * e {
            Some(format!("relative energy decrease below {:.0e}", self.relative_tolerance))
        } else if moved <= self.prediction_tolerance.max(0.05 * rms) {
            Some("no training prediction moved by the tolerance or 5 % of the RMS residual".into())
        } else {
            None
        }
    }
}

/// Levenberg–Marquardt (the one least-squares driver, `numeric::levenberg_marquardt`) on
/// ½ |k1(z) − y|²/σ² + ½ |z|² from `z`: pure Gauss–Newton until a step fails, then damping 1e-6,
/// ×100 per failure, ×0.1 per success; converged when an accepted step
/// lowers the energy by at most `relative_tolerance` of it or moves no training prediction by more
/// than `prediction_tolerance` (internal units) or 5 % of the RMS training residual, or when no step
/// lowers it at damping up to 1e12: returns the whitened weights, the
/// final positions (internal units), the iterations (every trial counts) and whether it converged.
pub fn minimise(
    problem: &StageProblem<'_>,
    z: Vec<f64>,
    max_iterations: usize,
    relative_tolerance: f64,
    prediction_tolerance: f64,
) -> Option<(Vec<f64>, Vec<f64>, usize, bool)> {
    let (k, jac) = problem.evaluate(&z, true)?;
    let e = energy_of(problem, &k, &z);
    let options = lm::Options {
        damping: lm::Damping::Marquardt { first: 1e-6, growth: 100.0, limit: 1e12, relax: lm::Relax::Scale(0.1) },
        acceptance: lm::Acceptance::Decrease,
        counting: lm::Counting::Trials,
        first_iteration: 1,
        max_iterations,
    };
    let mut steps = WeightSteps { problem, relative_tolerance, prediction_tolerance };
    let found = lm::minimise(&mut steps, z, (k, jac, e), &options).ok()?;
    let converged = found.stop != lm::Stop::IterationLimit;
    Some((found.x, found.at.0, found.iterations, converged))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::axis_forms::joint_series;
    use crate::expansion::basis::{truncate, AxisSeries};
    use crate::flow::ControlPoints;
    use cbd_protocol::*;

    /// ∂k1/∂z of the tangent against central differences of k1, for Euler × 2 and Heun × 2 on the
    /// RR arm (normalised task space, flat kernels, weights large enough to move the arm).
    #[test]
    fn tangent_matches_central_differences() {
        let nominal = crate::simulate::rr::nominal();
        let points = crate::simulate::configurations(crate::simulate::Sampling::Uniform { count: 7, seed: 3 }, 2);
        let kernel = JointKernel {
            gamma: 0.3,
            axes: heapless::Vec::from_slice(&[JointKernelAxis::Periodic { b: 0.2 }, JointKernelAxis::Periodic { b: 0.5 }]).unwrap(),
        };
        let task_kernel = TaskKernel { width: 1.5 };
        for integrator in
            [Integrator { method: IntegratorMethod::Euler, steps: 2 }, Integrator { method: IntegratorMethod::Heun, steps: 2 }]
        {
            let cp = ControlPoints::new(
                &nominal,
                &Normalisation::IDENTITY,
                points.clone(),
                kernel.clone(),
                task_kernel,
                MomentumLaw::Hamiltonian,
                integrator,
            );
            let initial = cp.nominal_kinematics();
            let joint = truncate(&joint_series(&kernel, &[4.0, 4.0]).unwrap(), 1e-6).unwrap();
            let task = truncate(&vec![AxisSeries::gaussian(1.8 / 1.5); 2], 1e-6).unwrap();
            let target = vec![0.0; 14];
            let problem = StageProblem::new(cp.dims, &cp.points, initial, &target, &kernel, &task_kernel, &joint, &task, 1e-3, integrator);
            let mut s = 7u64;
            let z: Vec<f64> = (0..problem.stage_len() * integrator.stage_count())
                .map(|_| {
                    s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                    ((s >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 0.6
                })
                .collect();
            let (k, jac) = problem.evaluate(&z, true).unwrap();
            let jac = jac.unwrap();
            let moved = k.iter().zip(&cp.nominal_positions()).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
            assert!(moved > 0.05, "{integrator:?}: the weights barely move the arm ({moved})");
            let h = 1e-6;
            let mut worst = 0.0f64;
            for p in (0..z.len()).step_by(7) {
                let (mut zp, mut zm) = (z.clone(), z.clone());
                zp[p] += h;
                zm[p] -= h;
                let (kp, _) = problem.evaluate(&zp, false).unwrap();
                let (km, _) = problem.evaluate(&zm, false).unwrap();
                for r in 0..k.len() {
                    worst = worst.max(((kp[r] - km[r]) / (2.0 * h) - jac[(r, p)]).abs());
                }
            }
            assert!(worst < 1e-7, "{integrator:?}: tangent vs central differences {worst:e}");
        }
    }
}

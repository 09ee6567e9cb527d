//! The weight-space evidence and its gradient. With A' = A Λ^½ (whitened design), M = I + A'ᵀA'/σ²,
//! w̄ = M⁻¹ A'ᵀ r / σ² (the posterior mean, whitened) and e = r − A' w̄ (the residual):
//!
//! ```text
//! nlml = ½ (|e|²/σ² + |w̄|²) + ½ (N m ln σ² + ln det M) + ½ N m ln 2π
//! ∂/∂ ln λ_k = ½ (1 − (M⁻¹)_kk − w̄_k²)                          (prior variances: b_d, γ_V, γ_W)
//! ∂/∂ ln a   = σ⁻² (tr(M⁻¹ A'ᵀ ∂A') − eᵀ ∂A' w̄)                 (task functions move with a)
//! ∂/∂ ln σ   = N m − r + tr M⁻¹ − |e|²/σ²
//! ```
//!
//! the kernel form's ½ tr((K⁻¹ − ααᵀ) ∂K) rewritten with K⁻¹A' = A'M⁻¹/σ² and α = e/σ².
//! A geometric group's explicit columns (prior-scaled, weights N(0, I)) join A' after the kernels'
//! weights: fixed in θ, they enter M, w̄, e, ln det M and the a and σ gradients, and have no
//! variance gradient of their own.

use super::super::search::Criterion;
use super::super::table::Theta;
use super::prior::PeriodicShares;
use super::WeightSpaceTable;
use crate::numeric::FIXED_SPLIT;
use cbd_runtime::internals::expansion::for_each_task_basis;
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::llt::factor::{cholesky_in_place, cholesky_in_place_scratch};
use faer::linalg::cholesky::llt::inverse::{inverse as llt_inverse, inverse_scratch as llt_inverse_scratch};
use faer::linalg::matmul::matmul;
use faer::linalg::triangular_solve::{solve_lower_triangular_in_place, solve_upper_triangular_in_place};
use faer::{Accum, Mat};

/// aᵀ b on the fixed split.
fn transposed_product(a: &Mat<f64>, b: &Mat<f64>) -> Mat<f64> {
    let mut out = Mat::zeros(a.ncols(), b.ncols());
    matmul(out.as_mut(), Accum::Replace, a.transpose(), b.as_ref(), 1.0, FIXED_SPLIT);
    out
}

impl Criterion for WeightSpaceTable {
    fn observations(&self) -> usize {
        self.count * self.m
    }

    /// Absolute, not per unknown ([`super::absolute_tolerances`]).
    fn tolerances(&self) -> (f64, f64) {
        super::absolute_tolerances(self.observations())
    }

    fn nlml_and_gradient(&self, packed: &[f64]) -> Option<(f64, Vec<f64>)> {
        let theta = Theta::unpack(packed, self.n);
        let (n, m, count) = (self.n, self.m, self.count);
        let (gv, gw, a) = (theta.log_gamma_v.exp(), theta.log_gamma_w.exp(), theta.log_a.exp());
        let sigma2 = (2.0 * theta.log_sigma).exp();
        let (r_j, r_t) = (self.joint_functions, self.task_functions());
        let joint_width = r_j * n;
        let kernel_weights = self.weights();
        let geo = self.explicit_columns();
        // Every column of A': the kernels' weights, then the explicit ones.
        let r = kernel_weights + geo;
        // Joint prior variances λ_f = γ_V Π_d ω_{h_d}(b_d) and their d ln λ_f / d ln b_d.
        let prior = PeriodicShares::new(&theta.log_widths, &self.joint_orders);
        let orders = |f: usize| &self.joint_orders[f * n..(f + 1) * n];
        let lambda: Vec<f64> = prior.shares.iter().map(|s| gv * s).collect();
        // Whitening per column: √λ_f for every joint column of f, √γ_W for the task columns.
        let scale: Vec<f64> = (0..r)
            .map(|k| {
                if k < joint_width {
                    lambda[k / n].sqrt()
                } else if k < kernel_weights {
                    gw.sqrt()
                } else {
                    1.0
                }
            })
            .collect();
        // Task functions at width a, and their derivatives in ln a: ψ (|y|²/a² − |α|).
        let kernel = WeightSpaceTable::task_kernel(a);
        let (mut psi, mut psi_a) = (Mat::<f64>::zeros(count, r_t), Mat::<f64>::zeros(count, r_t));
        let inv_a2 = 1.0 / (a * a);
        for i in 0..count {
            let y = &self.nominal[i * m..(i + 1) * m];
            for_each_task_basis(&kernel, &self.task_exponents, m, y, false, |g, v, _, _| {
                psi[(i, g)] = v;
                psi_a[(i, g)] = v * (self.radius2[i] * inv_a2 - self.task_degrees[g]);
            });
        }
        let task_col = |g: usize, c: usize| joint_width + g * m + c;
        // M = I + A'ᵀA'/σ², block by block.
        let mut mm = Mat::<f64>::zeros(r, r);
        for l in 0..joint_width {
            for k in 0..joint_width {
                mm[(k, l)] = scale[k] * scale[l] * self.joint_gram[(k, l)] / sigma2;
            }
        }
        let joint_task: Vec<Mat<f64>> = self.joint_columns.iter().map(|ac| transposed_product(ac, &psi)).collect();
        let joint_task_a: Vec<Mat<f64>> = self.joint_columns.iter().map(|ac| transposed_product(ac, &psi_a)).collect();
        let task_task = transposed_product(&psi, &psi);
        let task_task_a = transposed_product(&psi, &psi_a);
        for c in 0..m {
            for g in 0..r_t {
                let col = task_col(g, c);
                for k in 0..joint_width {
                    let v = scale[k] * scale[col] * joint_task[c][(k, g)] / sigma2;
                    mm[(k, col)] = v;
                    mm[(col, k)] = v;
                }
                for h in 0..r_t {
                    mm[(task_col(h, c), col)] = gw * task_task[(h, g)] / sigma2;
                }
            }
        }
        // The explicit columns: fixed blocks, and their products with the task functions at width a.
        let explicit_task: Vec<Mat<f64>> = self.explicit.iter().map(|g| transposed_product(g, &psi)).collect();
        let explicit_task_a: Vec<Mat<f64>> = self.explicit.iter().map(|g| transposed_product(g, &psi_a)).collect();
        for j in 0..geo {
            let row = kernel_weights + j;
            for l in 0..geo {
                mm[(row, kernel_weights + l)] = self.explicit_gram[(j, l)] / sigma2;
            }
            for k in 0..joint_width {
                let v = scale[k] * self.explicit_joint[(j, k)] / sigma2;
                mm[(row, k)] = v;
                mm[(k, row)] = v;
            }
            for c in 0..m {
                for g in 0..r_t {
                    let v = gw.sqrt() * explicit_task[c][(j, g)] / sigma2;
                    mm[(row, task_col(g, c))] = v;
                    mm[(task_col(g, c), row)] = v;
                }
            }
        }
        for k in 0..r {
            mm[(k, k)] += 1.0;
        }
        // A'ᵀ r / σ².
        let task_residual: Vec<Mat<f64>> = self.residual.iter().map(|rc| transposed_product(&psi, rc)).collect();
        let mut w = Mat::from_fn(r, 1, |k, _| {
            let v = if k < joint_width {
                self.joint_residual[k]
            } else if k < kernel_weights {
                task_residual[(k - joint_width) % m][((k - joint_width) / m, 0)]
            } else {
                self.explicit_residual[k - kernel_weights]
            };
            scale[k] * v / sigma2
        });
        let mut l = mm;
        let mut mem = MemBuffer::new(cholesky_in_place_scratch::<f64>(r, FIXED_SPLIT, Default::default()));
        cholesky_in_place(l.as_mut(), Default::default(), FIXED_SPLIT, MemStack::new(&mut mem), Default::default()).ok()?;
        let logdet: f64 = 2.0 * (0..r).map(|k| l[(k, k)].ln()).sum::<f64>();
        solve_lower_triangular_in_place(l.as_ref(), w.as_mut(), FIXED_SPLIT);
        solve_upper_triangular_in_place(l.as_ref().transpose(), w.as_mut(), FIXED_SPLIT);
        // e = r − A' w̄, per coordinate.
        let joint_weights = Mat::from_fn(joint_width, 1, |k, _| scale[k] * w[(k, 0)]);
        let explicit_weights = Mat::from_fn(geo, 1, |j, _| w[(kernel_weights + j, 0)]);
        let mut e2 = 0.0;
        let mut residuals = Vec::with_capacity(m);
        for c in 0..m {
            let task_weights = Mat::from_fn(r_t, 1, |g, _| gw.sqrt() * w[(task_col(g, c), 0)]);
            let mut ec = self.residual[c].clone();
            matmul(ec.as_mut(), Accum::Add, self.joint_columns[c].as_ref(), joint_weights.as_ref(), -1.0, FIXED_SPLIT);
            matmul(ec.as_mut(), Accum::Add, psi.as_ref(), task_weights.as_ref(), -1.0, FIXED_SPLIT);
            matmul(ec.as_mut(), Accum::Add, self.explicit[c].as_ref(), explicit_weights.as_ref(), -1.0, FIXED_SPLIT);
            e2 += (0..count).map(|i| ec[(i, 0)] * ec[(i, 0)]).sum::<f64>();
            residuals.push(ec);
        }
        let w2: f64 = (0..r).map(|k| w[(k, 0)] * w[(k, 0)]).sum();
        let observations = (count * m) as f64;
        let value =
            0.5 * (e2 / sigma2 + w2) + 0.5 * (observations * sigma2.ln() + logdet) + 0.5 * observations * (2.0 * std::f64::consts::PI).ln();
        if !value.is_finite() {
            return None;
        }
        // M⁻¹ (lower triangle).
        let mut inv = Mat::<f64>::zeros(r, r);
        let mut mem = MemBuffer::new(llt_inverse_scratch::<f64>(r, FIXED_SPLIT));
        llt_inverse(inv.as_mut(), l.as_ref(), FIXED_SPLIT, MemStack::new(&mut mem));
        let inv_at = |i: usize, j: usize| inv[(i.max(j), i.min(j))];
        let variance_gradient: Vec<f64> = (0..r).map(|k| 0.5 * (1.0 - inv_at(k, k) - w[(k, 0)] * w[(k, 0)])).collect();
        let mut grad = vec![0.0; n + 4];
        for k in 0..joint_width {
            let f = k / n;
            for (d, &h) in orders(f).iter().enumerate() {
                grad[d] += variance_gradient[k] * prior.log_derivatives[d][h];
            }
            grad[n] += variance_gradient[k];
        }
        grad[n + 2] = variance_gradient[joint_width..kernel_weights].iter().sum();
        // ln a: tr(M⁻¹ A'ᵀ ∂A') − eᵀ ∂A' w̄ over the task columns, ∂A' = √γ_W ψ_a on its coordinate.
        let mut trace = 0.0;
        let mut along = 0.0;
        for c in 0..m {
            let residual_a = transposed_product(&psi_a, &residuals[c]);
            for g in 0..r_t {
                let col = task_col(g, c);
                let mut s = 0.0;
                for j in 0..joint_width {
                    s += inv_at(col, j) * scale[j] * scale[col] * joint_task_a[c][(j, g)];
                }
                for h in 0..r_t {
                    s += inv_at(col, task_col(h, c)) * gw * task_task_a[(h, g)];
                }
                for j in 0..geo {
                    s += inv_at(col, kernel_weights + j) * scale[col] * explicit_task_a[c][(j, g)];
                }
                trace += s;
                along += residual_a[(g, 0)] * scale[col] * w[(col, 0)];
            }
        }
        grad[n + 1] = (trace - along) / sigma2;
        let trace_inv: f64 = (0..r).map(|k| inv_at(k, k)).sum();
        grad[n + 3] = observations - r as f64 + trace_inv - e2 / sigma2;
        grad.iter().all(|g| g.is_finite()).then_some((value, grad))
    }
}

//! Leave-one-row-out cross-validation of the linearised model, in closed form, with its gradient.
//!
//! Leaving row i out, the GP's prediction error on its m coordinates is e_i = B_i⁻¹ α_i, with
//! Z = K⁻¹, B_i = Z_ii (its m × m diagonal block) and α = Z r (Rasmussen & Williams §5.4.2, in block
//! form). The criterion is L = Σ_i |e_i|² / N. With g_i = B_i⁻¹ e_i, dZ = −Z dK Z and dα = −Z dK α:
//! dL = (2/N) tr(dK M), M = Z E Z − α (Z u)ᵀ, E = blockdiag(e_i g_iᵀ), u = (g_i) stacked;
//! Z E Z = A Cᵀ with columns a_i = Z_{:,i} e_i, c_i = Z_{:,i} g_i, and Z u = Σ_i c_i.

use super::table::{PairTable, Theta};
use faer::linalg::matmul::matmul;
use faer::{Accum, Mat};

impl PairTable {
    /// Mean squared leave-one-row-out position error (normalised units²) at θ (packed), and its
    /// gradient; None when K is not positive definite.
    pub(crate) fn loo_and_gradient(&self, packed: &[f64]) -> Option<(f64, Vec<f64>)> {
        let theta = Theta::unpack(packed, self.n);
        let (m, dim, count) = (self.m, self.dim(), self.count);
        let f = self.factor(&theta)?;
        // Per row: e_i and g_i as columns i of dim × count matrices placed in row block i.
        let mut e_placed = Mat::<f64>::zeros(dim, count);
        let mut g_placed = Mat::<f64>::zeros(dim, count);
        let mut sum = 0.0;
        for i in 0..count {
            let block = Mat::from_fn(m, m, |a, b| f.inv_at(i * m + a, i * m + b));
            let llt = block.llt(faer::Side::Lower).ok()?;
            let rhs = Mat::from_fn(m, 1, |a, _| f.alpha[(i * m + a, 0)]);
            let e = faer::linalg::solvers::Solve::solve(&llt, &rhs);
            let g = faer::linalg::solvers::Solve::solve(&llt, &e);
            for a in 0..m {
                e_placed[(i * m + a, i)] = e[(a, 0)];
                g_placed[(i * m + a, i)] = g[(a, 0)];
                sum += e[(a, 0)] * e[(a, 0)];
            }
        }
        let value = sum / count as f64;
        if !value.is_finite() {
            return None;
        }
        let par = crate::solver::FIXED_SPLIT;
        let z = Mat::from_fn(dim, dim, |r, c| f.inv_at(r, c));
        let product = |a: &Mat<f64>, b: faer::MatRef<'_, f64>| {
            let mut out = Mat::zeros(a.nrows(), b.ncols());
            matmul(out.as_mut(), Accum::Replace, a.as_ref(), b, 1.0, par);
            out
        };
        let a = product(&z, e_placed.as_ref());
        let c = product(&z, g_placed.as_ref());
        let mut mm = product(&a, c.as_ref().transpose());
        let zu: Vec<f64> = (0..dim).map(|r| (0..count).map(|i| c[(r, i)]).sum()).collect();
        for (col, zu_col) in zu.iter().enumerate() {
            for row in 0..dim {
                mm[(row, col)] -= f.alpha[(row, 0)] * zu_col;
            }
        }
        // dL = (2/N) tr(dK M) = ½ tr(Q dK) with Q = (4/N) sym(M).
        let scale = 2.0 / count as f64;
        let grad = self.half_trace_gradient(&theta, &f, |r, c| scale * (mm[(r, c)] + mm[(c, r)]));
        Some((value, grad))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::simulate::{configurations, rr, Sampling};

    /// The closed form against refitting without each row, and the gradient against finite differences.
    #[test]
    fn leave_one_out_matches_refits_and_its_gradient_finite_differences() {
        let data = rr::RealRr::default().measure(&configurations(Sampling::Uniform { count: 12, seed: 4 }, 2));
        let norm = crate::kernels::normalisation_of(&data);
        let nominal = rr::nominal();
        let table = PairTable::new(&nominal, &data, &norm);
        let theta = Theta { log_widths: vec![0.3f64.ln(), 1.7f64.ln()], log_gamma_v: -3.0, log_a: 0.2, log_gamma_w: -4.0, log_sigma: -4.0 };
        let p = theta.pack();
        let (value, grad) = table.loo_and_gradient(&p).unwrap();
        // Refits: the GP posterior mean at row i from the other rows, K_{i,rest} K_rest⁻¹ r_rest.
        let (k, _, _) = table.covariance(&theta);
        let (m, count) = (table.m, table.count);
        let mut sum = 0.0;
        for i in 0..count {
            let rest: Vec<usize> = (0..count * m).filter(|r| r / m != i).collect();
            let k_rest = Mat::from_fn(rest.len(), rest.len(), |a, b| k[(rest[a], rest[b])]);
            let r_rest = Mat::from_fn(rest.len(), 1, |a, _| table.residual[rest[a]]);
            let w = faer::linalg::solvers::Solve::solve(&k_rest.llt(faer::Side::Lower).unwrap(), &r_rest);
            for a in 0..m {
                let mean: f64 = (0..rest.len()).map(|b| k[(i * m + a, rest[b])] * w[(b, 0)]).sum();
                sum += (table.residual[i * m + a] - mean).powi(2);
            }
        }
        let refit = sum / count as f64;
        assert!((value - refit).abs() <= 1e-8 * refit, "closed form {value:e} vs refits {refit:e}");
        for k in 0..p.len() {
            let h = 1e-5;
            let (mut a, mut b) = (p.clone(), p.clone());
            a[k] += h;
            b[k] -= h;
            let fd = (table.loo_and_gradient(&a).unwrap().0 - table.loo_and_gradient(&b).unwrap().0) / (2.0 * h);
            assert!((fd - grad[k]).abs() <= 1e-6 * fd.abs().max(value), "θ[{k}]: analytic {} vs finite differences {fd}", grad[k]);
        }
    }
}

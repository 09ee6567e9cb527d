//! The kernel matrix of CbD's linearised model, tabulated per pair of rows so that each θ costs one
//! or two `exp` per pair, its factorisation, and the gradient of any criterion of the form ½ tr(Q dK);
//! and the scales read off it that set where the evidence search starts and the box it stays in
//! ([`DataScales`]: the residual's variance, the mean |Dk0|² and the joints' spread).

use crate::data::Measurements;
use crate::evidence::joint_pair_table::JointPairTable;
use crate::solver::regulariser::assemble_k_lin;
use cbd_protocol::{NominalModel, Normalisation};
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::llt::factor::{cholesky_in_place, cholesky_in_place_scratch};
use faer::linalg::cholesky::llt::inverse::{inverse as llt_inverse, inverse_scratch as llt_inverse_scratch};
use faer::linalg::triangular_solve::{solve_lower_triangular_in_place, solve_upper_triangular_in_place};
use faer::Mat;

/// Per pair of rows (lower triangle, i ≥ j, row-major): the joint kernel's per-axis exponent terms
/// ([`JointPairTable`]), J_i J_jᵀ and |k0_i − k0_j|², normalised units. Each likelihood evaluation
/// then costs one or two `exp` per pair.
pub(crate) struct PairTable {
    pub(super) n: usize,
    pub(super) m: usize,
    pub(super) count: usize,
    /// The joint kernel's exponent terms per pair and axis.
    pub(super) joint: JointPairTable,
    /// Per pair: J_i J_jᵀ, m × m row-major.
    pub(super) jj: Vec<f64>,
    pub(super) dist2: Vec<f64>,
    /// N m residual (y − k0)/scale, row-major (plus the geometric group's shift when it has one).
    pub(super) residual: Vec<f64>,
    /// G Gᵀ of the geometric group's explicit basis functions ([`super::geometry`]): added to
    /// every covariance, fixed in θ.
    pub(super) explicit: Option<Mat<f64>>,
    /// The residual's variance per coordinate that the fields are left to explain (without the
    /// geometric group's shift): the data scale of the starts and bounds.
    pub(super) fields_variance: f64,
}

impl PairTable {
    pub(crate) fn new(nominal: &NominalModel, data: &Measurements, norm: &Normalisation) -> Self {
        let (n, m, count) = (data.n_joints, data.task_dim, data.len());
        let kin: Vec<_> = (0..count).map(|i| crate::nominal::row_kinematics(nominal, data.joints(i), i).normalised(norm)).collect();
        let residual: Vec<f64> = (0..count)
            .flat_map(|i| {
                let (y, k) = (data.position(i), &kin[i]);
                (0..m).map(move |c| norm.position_to_internal(c, y[c]) - k.position[c])
            })
            .collect();
        let pairs = count * (count + 1) / 2;
        let (mut jj, mut dist2) = (Vec::with_capacity(pairs * m * m), Vec::with_capacity(pairs));
        for i in 0..count {
            for j in 0..=i {
                for a in 0..m {
                    for b in 0..m {
                        jj.push((0..n).map(|d| kin[i].jacobian[a][d] * kin[j].jacobian[b][d]).sum());
                    }
                }
                dist2.push((0..m).map(|c| (kin[i].position[c] - kin[j].position[c]).powi(2)).sum());
            }
        }
        let fields_variance = variance(&residual);
        PairTable {
            n,
            m,
            count,
            joint: JointPairTable::new(crate::axis_forms::forms_of(nominal), data),
            jj,
            dist2,
            residual,
            explicit: None,
            fields_variance,
        }
    }

    /// The table of "CbD with the geometry calibrated": `nominal` the fitted chain, the residual
    /// shifted back to the nominal's (to first order) and the group's G Gᵀ in every covariance.
    pub(crate) fn with_geometry(mut self, basis: &super::GeometricBasis) -> Self {
        for (r, s) in self.residual.iter_mut().zip(&basis.shift) {
            *r += s;
        }
        let g = basis.matrix();
        let mut ggt = Mat::<f64>::zeros(g.nrows(), g.nrows());
        faer::linalg::matmul::matmul(ggt.as_mut(), faer::Accum::Replace, g.as_ref(), g.transpose(), 1.0, crate::numeric::FIXED_SPLIT);
        self.explicit = Some(ggt);
        self
    }

    pub(super) fn dim(&self) -> usize {
        self.count * self.m
    }

    /// K_lin + σ² I for θ (normalised units), and per pair the unit kernels K̃_V, K̃_W and, with the
    /// configuration term, K̃_C = K̃_Q(q, q') K̃_X(k0, k0') (docs/DESIGN.md §16).
    pub(super) fn covariance(&self, theta: &Theta) -> (Mat<f64>, Vec<f64>, Vec<f64>, Vec<f64>) {
        let m = self.m;
        let w = self.joint.axis_weights(&theta.log_widths);
        let (gv, gw, sigma2) = (theta.log_gamma_v.exp(), theta.log_gamma_w.exp(), (2.0 * theta.log_sigma).exp());
        let inv_2a2 = 0.5 * (-2.0 * theta.log_a).exp();
        let config = theta.config.as_ref().map(|c| (self.joint.axis_weights(&c.log_widths), c.task_factor_weight(), c.log_gamma.exp()));
        let gc = config.as_ref().map_or(0.0, |c| c.2);
        let dim = self.dim();
        let pairs = self.dist2.len();
        let (mut kv_all, mut kw_all) = (Vec::with_capacity(pairs), Vec::with_capacity(pairs));
        let mut kc_all = Vec::with_capacity(if config.is_some() { pairs } else { 0 });
        let mut k = assemble_k_lin(self.count, m, gv, gw, gc, |i, j, jj| {
            let at = JointPairTable::pair_index(i, j);
            let (kv, kw) = (self.joint.unit_kernel(at, &w), (-self.dist2[at] * inv_2a2).exp());
            // K̃_C = exp(Σ_d c_d f_d) · exp(−|k0_i − k0_j|² / 2a_C²) (the second factor 1 when flat).
            let kc = config.as_ref().map_or(0.0, |(c, inv_2ac2, _)| self.joint.unit_kernel(at, c) * (-self.dist2[at] * inv_2ac2).exp());
            jj.copy_from_slice(&self.jj[at * m * m..(at + 1) * m * m]);
            kv_all.push(kv);
            kw_all.push(kw);
            if config.is_some() {
                kc_all.push(kc);
            }
            (kv, kw, kc)
        });
        for r in 0..dim {
            k[(r, r)] += sigma2;
        }
        if let Some(ggt) = &self.explicit {
            k += ggt;
        }
        (k, kv_all, kw_all, kc_all)
    }

    /// K = K_lin + σ² I at θ factored: L and α = K⁻¹ r, on the solver's fixed split (the result
    /// never depends on the thread count). None when K is not positive definite. K⁻¹, which only the
    /// gradient needs, is [`Factored::inverse`]: twice the factorisation's flops again.
    pub(super) fn factor(&self, theta: &Theta) -> Option<Factored> {
        let dim = self.dim();
        let (k, kv, kw, kc) = self.covariance(theta);
        let par = crate::numeric::FIXED_SPLIT;
        let mut l = k;
        let mut mem = MemBuffer::new(cholesky_in_place_scratch::<f64>(dim, par, Default::default()));
        cholesky_in_place(l.as_mut(), Default::default(), par, MemStack::new(&mut mem), Default::default()).ok()?;
        let lower = l.as_ref();
        let mut alpha = Mat::from_fn(dim, 1, |i, _| self.residual[i]);
        solve_lower_triangular_in_place(lower, alpha.as_mut(), par);
        // rᵀ K⁻¹ r = |L⁻¹ r|², before the second solve.
        let quad: f64 = (0..dim).map(|i| alpha[(i, 0)] * alpha[(i, 0)]).sum();
        solve_upper_triangular_in_place(lower.transpose(), alpha.as_mut(), par);
        Some(Factored { l, alpha, quad, kv, kw, kc })
    }

    /// ½ tr(Q ∂K/∂θ) for every θ component, Q symmetric (given by its entries), accumulated over
    /// the pairs: the gradient of any criterion whose differential is ½ tr(Q dK).
    pub(super) fn half_trace_gradient(&self, theta: &Theta, f: &Factored, q: impl Fn(usize, usize) -> f64) -> Vec<f64> {
        let (n, m, dim) = (self.n, self.m, self.dim());
        let (gv, gw) = (theta.log_gamma_v.exp(), theta.log_gamma_w.exp());
        let inv_a2 = (-2.0 * theta.log_a).exp();
        let w = self.joint.axis_weights(&theta.log_widths);
        let config = theta.config.as_ref().map(|c| (self.joint.axis_weights(&c.log_widths), c.task_factor_weight(), c.log_gamma.exp()));
        // θ's packed order: widths, γ_V, a, γ_W, [c_1..c_n, a_C, γ_C], σ.
        let mut grad = vec![0.0; theta.len()];
        let mut at = 0;
        for i in 0..self.count {
            for j in 0..=i {
                // ½ tr(Q ∂K) over both (i, j) and (j, i) blocks: ½ (2 · lower + diagonal).
                let weight = if i == j { 0.5 } else { 1.0 };
                let jj = &self.jj[at * m * m..(at + 1) * m * m];
                let mut s = 0.0;
                let mut t = 0.0;
                for a in 0..m {
                    for b in 0..m {
                        s += q(i * m + a, j * m + b) * jj[a * m + b];
                    }
                    t += q(i * m + a, j * m + a);
                }
                let s = weight * s * gv * f.kv[at];
                let t = weight * t;
                let terms = self.joint.terms_of(at);
                for d in 0..n {
                    // The form's ∂(w t)/∂ log p: periodic ∂(b f)/∂ log b = b f; Gaussian ∂(f/ℓ²)/∂ log ℓ = −2 f/ℓ².
                    let dexp = self.joint.forms[d].exponent_log_derivative(w[d], terms[d]);
                    grad[d] += s * dexp;
                }
                grad[n] += s;
                let tw = t * gw * f.kw[at];
                grad[n + 1] += tw * self.dist2[at] * inv_a2;
                grad[n + 2] += tw;
                if let Some((c, inv_2ac2, gc)) = &config {
                    // ∂(γ_C K̃_Q K̃_X)/∂ log c_d = γ_C K̃_C c_d f_d (form's rule), ∂/∂ log a_C = γ_C K̃_C |Δk0|²/a_C², ∂/∂ log γ_C = γ_C K̃_C.
                    let tc = t * gc * f.kc[at];
                    for d in 0..n {
                        grad[n + 3 + d] += tc * self.joint.forms[d].exponent_log_derivative(c[d], terms[d]);
                    }
                    grad[2 * n + 3] += tc * self.dist2[at] * 2.0 * inv_2ac2;
                    grad[2 * n + 4] += tc;
                }
                at += 1;
            }
        }
        let sigma2 = (2.0 * theta.log_sigma).exp();
        // ½ tr(Q ∂K/∂ log σ), ∂K/∂ log σ = 2σ² I.
        let last = grad.len() - 1;
        grad[last] = sigma2 * (0..dim).map(|i| q(i, i)).sum::<f64>();
        grad
    }
}

/// Mean square of `v` (floored: a residual of zeros still sets finite scales).
fn variance(v: &[f64]) -> f64 {
    (v.iter().map(|x| x * x).sum::<f64>() / v.len().max(1) as f64).max(1e-30)
}

/// K = K_lin + σ² I at one θ, factored.
pub(super) struct Factored {
    /// Cholesky factor, lower triangle.
    pub l: Mat<f64>,
    /// K⁻¹ r.
    pub alpha: Mat<f64>,
    /// rᵀ K⁻¹ r.
    pub quad: f64,
    /// Per pair, the unit kernels K̃_V and K̃_W.
    pub kv: Vec<f64>,
    pub kw: Vec<f64>,
    /// Per pair, K̃_C (empty without the configuration term).
    pub kc: Vec<f64>,
}

impl Factored {
    /// K⁻¹ = L⁻ᵀ L⁻¹, lower triangle only (faer's triangular inverse and product: n³ flops).
    pub fn inverse(&self) -> Inverse {
        let dim = self.l.nrows();
        let par = crate::numeric::FIXED_SPLIT;
        let mut inv = Mat::<f64>::zeros(dim, dim);
        let mut mem = MemBuffer::new(llt_inverse_scratch::<f64>(dim, par));
        llt_inverse(inv.as_mut(), self.l.as_ref(), par, MemStack::new(&mut mem));
        Inverse(inv)
    }
}

/// K⁻¹, lower triangle.
pub(super) struct Inverse(Mat<f64>);

impl Inverse {
    /// (K⁻¹)_rc from the lower triangle.
    pub fn at(&self, r: usize, c: usize) -> f64 {
        self.0[(r.max(c), r.min(c))]
    }
}

/// θ in log form, normalised units.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct Theta {
    pub(super) log_widths: Vec<f64>,
    pub(super) log_gamma_v: f64,
    pub(super) log_a: f64,
    pub(super) log_gamma_w: f64,
    pub(super) log_sigma: f64,
    /// The configuration-dependent task term γ_C K̃_Q(q, q') K̃_X(k0, k0') I (docs/DESIGN.md §16), if in the model.
    pub(super) config: Option<ConfigTheta>,
}

/// The configuration term's θ (logs, normalised units): per-joint weights of K̃_Q in the joint
/// kernel's forms, the task width a_C (`None`: flat, K̃_X = 1) and the amplitude γ_C.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct ConfigTheta {
    pub(super) log_widths: Vec<f64>,
    pub(super) log_a: f64,
    pub(super) log_gamma: f64,
}

impl ConfigTheta {
    /// 1/(2 a_C²).
    pub(super) fn task_factor_weight(&self) -> f64 {
        0.5 * (-2.0 * self.log_a).exp()
    }
}

impl Theta {
    /// Packed length: n + 4, or 2n + 6 with the configuration term.
    pub(super) fn len(&self) -> usize {
        self.log_widths.len() + 4 + self.config.as_ref().map_or(0, |c| c.log_widths.len() + 2)
    }
    /// Packed: widths, γ_V, a, γ_W, [c_1..c_n, a_C, γ_C], σ (σ last: the search raises it first).
    pub(super) fn pack(&self) -> Vec<f64> {
        let mut v = self.log_widths.clone();
        v.extend([self.log_gamma_v, self.log_a, self.log_gamma_w]);
        if let Some(c) = &self.config {
            v.extend(&c.log_widths);
            v.extend([c.log_a, c.log_gamma]);
        }
        v.push(self.log_sigma);
        v
    }
    /// The inverse of [`Theta::pack`] for n joints: the configuration term when `p` has 2n + 6 entries.
    pub(super) fn unpack(p: &[f64], n: usize) -> Self {
        let config = (p.len() == 2 * n + 6).then(|| ConfigTheta {
            log_widths: p[n + 3..2 * n + 3].to_vec(),
            log_a: p[2 * n + 3],
            log_gamma: p[2 * n + 4],
        });
        Theta { log_widths: p[..n].to_vec(), log_gamma_v: p[n], log_a: p[n + 1], log_gamma_w: p[n + 2], log_sigma: p[p.len() - 1], config }
    }
}

/// Scales of the data that set the starts and the bounds (normalised units, logs where named so).
pub(super) struct DataScales {
    /// Residual variance per coordinate.
    var_r: f64,
    /// γ_V that gives the joint field half the residual's variance.
    gamma_v0: f64,
    /// Per axis, the log parameter (periodic b, Gaussian ℓ) at which typical pairs of rows have kernel ½.
    log_half: Vec<f64>,
    /// ln of the median distance from a row's nominal position to its nearest other row's.
    log_spacing: f64,
}

impl DataScales {
    pub fn of(table: &PairTable) -> Self {
        let m = table.m;
        let var_r = table.fields_variance;
        let count = table.count;
        let mean_jj =
            (0..count).map(|i| table.jj[(i * (i + 1) / 2 + i) * m * m..][..m * m].iter().step_by(m + 1).sum::<f64>()).sum::<f64>()
                / (count * m) as f64;
        // Typical pairs (the mean over every pair) at kernel ½.
        let log_half = table.joint.half_kernel_log_widths(0..table.dist2.len());
        let gamma_v0 = (0.5 * var_r / mean_jj.max(1e-30)).ln();
        DataScales { var_r, gamma_v0, log_half, log_spacing: median_spacing(table).ln() }
    }

    /// Per axis, the log parameter at which typical pairs of rows have kernel ½.
    pub fn log_half(&self) -> &[f64] {
        &self.log_half
    }

    /// Joint widths shifted by `shift` in log weight (log b; ℓ moves by half as much the other way).
    pub fn widths(&self, table: &PairTable, shift: f64) -> Vec<f64> {
        table.joint.forms.iter().zip(&self.log_half).map(|(f, l)| l + shift / f.log_weight_slope()).collect()
    }

    /// The four starts: balanced, smooth, nearly noise-free, rough.
    pub fn starts(&self, table: &PairTable) -> [Theta; 4] {
        let (var_r, gamma_v0) = (self.var_r, self.gamma_v0);
        [
            // Balanced: half the residual's variance to each field, noise a tenth.
            Theta {
                log_widths: self.widths(table, 0.0),
                log_gamma_v: gamma_v0,
                log_a: 0.0,
                log_gamma_w: (0.5 * var_r).ln(),
                log_sigma: 0.5 * (0.1 * var_r).ln(),
                config: None,
            },
            // Smooth: near-constant joint kernel (offsets and first harmonics) and a nearly affine task field.
            Theta {
                log_widths: self.widths(table, -4.0f64.ln() * 2.0),
                log_gamma_v: gamma_v0 + 100f64.ln(),
                log_a: 10f64.ln(),
                log_gamma_w: (100.0 * var_r).ln(),
                log_sigma: 0.5 * (1e-4 * var_r).ln(),
                config: None,
            },
            // Nearly noise-free: the balanced kernels, noise 1e-5 of the residual.
            Theta {
                log_widths: self.widths(table, 0.0),
                log_gamma_v: gamma_v0,
                log_a: 0.0,
                log_gamma_w: (0.5 * var_r).ln(),
                log_sigma: 0.5 * (1e-10 * var_r).ln(),
                config: None,
            },
            // Rough: narrow kernels, more noise.
            Theta {
                log_widths: self.widths(table, 4f64.ln()),
                log_gamma_v: gamma_v0,
                log_a: 0.3f64.ln(),
                log_gamma_w: (0.5 * var_r).ln(),
                log_sigma: 0.5 * (0.03 * var_r).ln(),
                config: None,
            },
        ]
    }

    /// The box θ stays in (lower, upper), packed like θ. The joint axes' each form's
    /// ([`crate::axis_forms::AxisForm::evidence_bounds`]: periodic b from 1e-5 to 1e3, Gaussian
    /// widths 1e±3 around the typical pair's), γ_V and γ_W from 1e-12 to 1e8 of the residual's
    /// scale, the task width from the rows' spacing (at least 1e-2) to 1e3, σ below.
    pub fn bounds(&self, table: &PairTable) -> (Vec<f64>, Vec<f64>) {
        let (n, var_r, gamma_v0) = (table.n, self.var_r, self.gamma_v0);
        let ln = |v: f64| v.ln();
        let mut lower = vec![0.0; n + 4];
        let mut upper = vec![0.0; n + 4];
        for d in 0..n {
            (lower[d], upper[d]) = table.joint.forms[d].evidence_bounds(self.log_half[d]);
        }
        (lower[n], upper[n]) = (gamma_v0 - ln(1e12), gamma_v0 + ln(1e8));
        // A task kernel narrower than the rows' spacing correlates almost no two measurements: the
        // evidence cannot tell it from noise, and a nearly equal basin where it stands in for σ (which
        // then drops to its floor) leaves no smooth task field — the six-joint arm with its geometry
        // marginalised: a = 8 mm, σ = 4e-7 mm, test error +12 %.
        (lower[n + 1], upper[n + 1]) = (ln(1e-2).max(self.log_spacing).min(ln(1e3)), ln(1e3));
        (lower[n + 2], upper[n + 2]) = (ln(var_r * 1e-12), ln(var_r * 1e8));
        // σ from 1e-8 of the residual's spread (and 1e-12 of the workspace) to three times it; a
        // residual below 1e-12 / √10 of the workspace (data a model fits exactly) leaves σ at the floor.
        let sigma_floor = (0.5 * ln(var_r * 1e-16)).max(ln(1e-12));
        (lower[n + 3], upper[n + 3]) = (sigma_floor, (0.5 * ln(var_r * 10.0)).max(sigma_floor));
        (lower, upper)
    }
}

/// The median over rows of the distance from a row's nominal position to the nearest other row's
/// (normalised units; 1e-2 for fewer than two rows or rows all at one point).
fn median_spacing(table: &PairTable) -> f64 {
    let count = table.count;
    let mut nearest: Vec<f64> = (0..count)
        .map(|i| {
            (0..count)
                .filter(|&j| j != i)
                .map(|j| table.dist2[JointPairTable::pair_index(i.max(j), i.min(j))])
                .fold(f64::INFINITY, f64::min)
        })
        .filter(|d| d.is_finite() && *d > 0.0)
        .collect();
    if nearest.is_empty() {
        return 1e-2;
    }
    nearest.sort_by(f64::total_cmp);
    nearest[nearest.len() / 2].sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::flow::ControlPoints;
    use crate::simulate::{configurations, rr, Sampling};
    use cbd_protocol::{Integrator, IntegratorMethod, JointKernel, JointKernelAxis, MomentumLaw, TaskKernel};

    /// The evidence's K_lin (its kernels tabulated per pair: std `cos` of the difference, one `exp`)
    /// against the fit's (`solver::regulariser`: the runtime's kernels from sin/cos features, libm),
    /// both from the one assembly: equal up to the kernels' rounding, pinned at 16 unit roundoffs
    /// (2⁻⁴⁸ = 3.6e-15) of the largest entry (measured: 3.4e-16 at b = (0.3, 1.7), 9.4e-16 at b = (8, 0.02)).
    #[test]
    fn the_evidences_k_lin_is_the_fits_to_a_stated_bound() {
        let data = rr::RealRr::default().measure(&configurations(Sampling::Uniform { count: 30, seed: 3 }, 2));
        let norm = data.normalisation();
        let nominal = rr::nominal();
        let table = PairTable::new(&nominal, &data, &norm);
        for log_widths in [vec![0.3f64.ln(), 1.7f64.ln()], vec![8f64.ln(), 0.02f64.ln()]] {
            let theta = Theta { log_widths, log_gamma_v: -3.0, log_a: 0.2, log_gamma_w: -4.0, log_sigma: -4.0, config: None };
            let (k, _, _, _) = table.covariance(&theta);
            let (gv, gw, sigma2) = (theta.log_gamma_v.exp(), theta.log_gamma_w.exp(), (2.0 * theta.log_sigma).exp());
            // The fit's kernels for θ: the blob's (γ = γ_V / γ_W, unit task kernel), K_lin = γ_W × that.
            let axes: Vec<JointKernelAxis> = theta.log_widths.iter().map(|l| JointKernelAxis::Periodic { b: l.exp() }).collect();
            let joint = JointKernel { gamma: gv / gw, axes: heapless::Vec::from_slice(&axes).unwrap() };
            let integrator = Integrator { method: IntegratorMethod::Euler, steps: 1 };
            let task = TaskKernel { width: theta.log_a.exp() };
            let cp = ControlPoints::new(&nominal, &norm, data.joints.clone(), joint, task, MomentumLaw::Hamiltonian, integrator);
            let fit = crate::solver::regulariser::regulariser_matrix(&cp);
            let dim = table.dim();
            let largest = (0..dim).map(|r| k[(r, r)]).fold(0.0f64, f64::max);
            let worst = (0..dim)
                .flat_map(|r| (0..dim).map(move |c| (r, c)))
                .map(|(r, c)| (k[(r, c)] - (gw * fit[(r, c)] + if r == c { sigma2 } else { 0.0 })).abs())
                .fold(0.0f64, f64::max);
            errln!(
                "b = {:?}: |K_evidence − K_fit| ≤ {:.3e} of the largest entry",
                theta.log_widths.iter().map(|l| l.exp()).collect::<Vec<_>>(),
                worst / largest
            );
            assert!(worst <= largest * 2f64.powi(-48), "{:e} of {largest:e}", worst / largest);
        }
    }
}

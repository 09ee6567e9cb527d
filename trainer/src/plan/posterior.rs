//! dh+cbd's linearised model as one Gaussian process conditioned pose by pose: CbD's kernel
//! (docs/DESIGN.md §3) plus the geometric group's Jacobian as basis functions with a broad prior
//! (the DH fit's least squares in the limit), so the two parts' errors are neither counted twice nor
//! chosen for separately; the posterior covariance at every tracked point kept by rank-m Cholesky
//! updates, never refactorised (docs/DESIGN.md §13).

use crate::evidence::CbdHyperparameters;
use cbd_protocol::{JointKernel, NominalModel, TaskKernel, MAX_JOINTS};
use cbd_runtime::internals::kernel::{joint_features, joint_kernel_from_features, FEATURES_PER_JOINT};
use cbd_runtime::internals::kinematics::forward_kinematics;

/// A configuration with what the kernel needs: k0, Dk0 (m × n, row-major), the joint features and
/// the geometric basis G = J_dh L (m × p, row-major; L L^T the parameters' prior covariance).
pub struct Point {
    position: [f64; 3],
    jacobian: Vec<f64>,
    features: [[f64; FEATURES_PER_JOINT]; MAX_JOINTS],
    geometric: Vec<f64>,
}

/// The prior: K_lin in the data's units, and the noise.
pub struct Prior {
    joint: JointKernel,
    task: TaskKernel,
    task_gamma: f64,
    pub sigma2: f64,
    m: usize,
    n: usize,
}

impl Prior {
    pub fn new(h: &CbdHyperparameters, m: usize) -> Self {
        let joint = JointKernel { gamma: h.joint_gamma, axes: heapless::Vec::from_slice(&h.joint_axes).unwrap_or_default() };
        Prior {
            n: h.joint_axes.len(),
            joint,
            task: TaskKernel { width: h.task_width },
            task_gamma: h.task_gamma,
            sigma2: h.sigma * h.sigma,
            m,
        }
    }

    /// `geometric`: G = J_dh L at `q` (m × p, row-major; empty without a geometric group).
    pub fn point(&self, nominal: &NominalModel, q: &[f64], geometric: Vec<f64>) -> Point {
        let k = forward_kinematics(nominal, q);
        let mut features = [[0.0; FEATURES_PER_JOINT]; MAX_JOINTS];
        joint_features(&self.joint, q, &mut features);
        let mut position = [0.0; 3];
        position[..self.m].copy_from_slice(&k.position[..self.m]);
        Point { position, jacobian: (0..self.m).flat_map(|c| (0..self.n).map(move |d| k.jacobian[c][d])).collect(), features, geometric }
    }

    /// tr K_lin(x, x): CbD's prior variance at `x`, the geometric part left out.
    pub fn cbd_variance(&self, x: &Point) -> f64 {
        let mut out = [0.0; 9];
        self.cbd_block(x, x, &mut out);
        (0..self.m).map(|r| out[r * self.m + r]).sum()
    }

    /// K_lin(x, x') + G(x) G(x')ᵀ, m × m row-major.
    fn block(&self, a: &Point, b: &Point, out: &mut [f64]) {
        self.cbd_block(a, b, out);
        let m = self.m;
        let p = a.geometric.len() / m;
        if p > 0 {
            for r in 0..m {
                for s in 0..m {
                    out[r * m + s] += (0..p).map(|k| a.geometric[r * p + k] * b.geometric[s * p + k]).sum::<f64>();
                }
            }
        }
    }

    /// K_lin(x, x') = K_V(x, x') Dk0(x) Dk0(x')ᵀ + γ_W K_W(k0(x), k0(x')) I, m × m row-major.
    fn cbd_block(&self, a: &Point, b: &Point, out: &mut [f64]) {
        let (m, n) = (self.m, self.n);
        let mut grad = [0.0; MAX_JOINTS];
        let kv = joint_kernel_from_features(&self.joint, &a.features[..n], &b.features[..n], &mut grad);
        let mut diff = [0.0; cbd_protocol::MAX_TASK_DIM];
        for c in 0..m {
            diff[c] = a.position[c] - b.position[c];
        }
        let mut tgrad = [0.0; cbd_protocol::MAX_TASK_DIM];
        let kw = self.task_gamma * cbd_runtime::internals::kernel::task_kernel(&self.task, &diff, m, &mut tgrad);
        for r in 0..m {
            for s in 0..m {
                let jj: f64 = (0..n).map(|d| a.jacobian[r * n + d] * b.jacobian[s * n + d]).sum();
                out[r * m + s] = kv * jj + if r == s { kw } else { 0.0 };
            }
        }
    }
}

/// The posterior given the poses added so far, at every tracked point: `candidates` first, then
/// `workspace` (the points whose variance the greedy step reduces), then the rest (evaluation
/// points, measured poses waiting to be added).
pub struct Posterior {
    prior: Prior,
    points: Vec<Point>,
    candidates: usize,
    workspace: usize,
    /// Per point: the rows of V = L⁻¹ k(S, x) (L the Cholesky factor of K_SS + σ²I), m per added
    /// or removed pose, k_S(x, y) = k(x, y) − Σ_g sign_g V_g(x)ᵀ V_g(y).
    v: Vec<Vec<f64>>,
    /// Per row group: 1 (a pose added) or −1 (removed).
    signs: Vec<f64>,
    /// Per point: its posterior covariance k_S(x, x), m × m.
    cov: Vec<f64>,
    /// Per candidate c and workspace point w: k_S(c, w), m × m.
    cross: Vec<f64>,
    /// Per candidate: Σ_w k_S(c, w) k_S(w, c), m × m, formed in the pass that updates `cross`.
    spread: Vec<f64>,
    added: usize,
}

impl Posterior {
    pub fn new(prior: Prior, points: Vec<Point>, candidates: usize, workspace: usize) -> Self {
        let m = prior.m;
        let mm = m * m;
        let mut cov = vec![0.0; points.len() * mm];
        for (i, p) in points.iter().enumerate() {
            prior.block(p, p, &mut cov[i * mm..(i + 1) * mm]);
        }
        let mut cross = vec![0.0; candidates * workspace * mm];
        for c in 0..candidates {
            for w in 0..workspace {
                let at = (c * workspace + w) * mm;
                prior.block(&points[c], &points[candidates + w], &mut cross[at..at + mm]);
            }
        }
        let v = (0..points.len()).map(|_| Vec::new()).collect();
        let mut spread = vec![0.0; candidates * mm];
        for c in 0..candidates {
            for w in 0..workspace {
                let at = (c * workspace + w) * mm;
                accumulate_outer(&mut spread[c * mm..(c + 1) * mm], &cross[at..at + mm], m);
            }
        }
        Posterior { prior, points, candidates, workspace, v, signs: Vec::new(), cov, cross, spread, added: 0 }
    }

    pub fn len(&self) -> usize {
        self.points.len()
    }

    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }

    pub fn sigma2(&self) -> f64 {
        self.prior.sigma2
    }

    /// Mean over the points `range` of tr k_S(x, x): the expected squared position error there.
    pub fn mean_variance(&self, range: std::ops::Range<usize>) -> f64 {
        let (m, count) = (self.prior.m, range.len().max(1) as f64);
        range.map(|i| (0..m).map(|c| self.cov[i * m * m + c * m + c]).sum::<f64>()).sum::<f64>() / count
    }

    /// tr k_S(x, x) at point `i`: its expected squared error given the poses added so far.
    pub fn variance(&self, i: usize) -> f64 {
        let m = self.prior.m;
        (0..m).map(|c| self.cov[i * m * m + c * m + c]).sum()
    }

    /// Reduction of the workspace's mean posterior variance if candidate `c` were measured:
    /// (1/|W|) Σ_w tr(k_S(w, c) (k_S(c, c) + σ²I)⁻¹ k_S(c, w)).
    pub fn gain(&self, c: usize) -> f64 {
        let mm = self.prior.m * self.prior.m;
        self.gain_from(&self.cov[c * mm..(c + 1) * mm], &self.spread[c * mm..(c + 1) * mm])
    }

    /// The gain of a candidate of posterior covariance `cov` and spread `b` = Σ_w k_S(c, w) k_S(w, c).
    fn gain_from(&self, cov: &[f64], b: &[f64]) -> f64 {
        let m = self.prior.m;
        let mut sc = [0.0; 9];
        sc[..m * m].copy_from_slice(&cov[..m * m]);
        for r in 0..m {
            sc[r * m + r] += self.prior.sigma2;
        }
        let Some(l) = cholesky(&sc, m) else { return 0.0 };
        // tr(S⁻¹ B) = Σ |L⁻¹ B^{1/2}|²: with S = L Lᵀ, tr(L⁻ᵀ L⁻¹ B) = tr(L⁻¹ B L⁻ᵀ).
        let lb = lower_solve(&l, b, m); // L⁻¹ B
        let lbl = lower_solve(&l, &transpose(&lb, m), m); // L⁻¹ (L⁻¹ B)ᵀ = L⁻¹ B L⁻ᵀ (B symmetric)
        (0..m).map(|r| lbl[r * m + r]).sum::<f64>() / self.workspace.max(1) as f64
    }

    /// Conditions on a measurement at point `s`: with t_x = k_S(s, x) and L_d Lᵀ_d = k_S(s, s) + σ²I,
    /// every point gains the rows u_x = L_d⁻¹ t_x, k_S(x, y) −= u_xᵀ u_y.
    pub fn add(&mut self, s: usize) -> bool {
        match self.rows_for(s, 1.0) {
            Some(u) => {
                self.apply(u, 1.0);
                true
            }
            None => false,
        }
    }

    /// Forgets the measurement at point `s` (added before): the inverse of [`Self::add`],
    /// k_{S∖s}(x, y) = k_S(x, y) + k_S(x, s) (σ²I − k_S(s, s))⁻¹ k_S(s, y) (the update formula solved
    /// for the prior; σ²I − k_S(s, s) = σ⁴ (k_{S∖s}(s, s) + σ²I)⁻¹ is positive definite).
    pub fn remove(&mut self, s: usize) -> bool {
        match self.rows_for(s, -1.0) {
            Some(u) => {
                self.apply(u, -1.0);
                true
            }
            None => false,
        }
    }

    /// The workspace's mean posterior variance, the quantity the greedy and exchange steps reduce.
    pub fn criterion(&self) -> f64 {
        self.mean_variance(self.candidates..self.candidates + self.workspace)
    }

    /// Per candidate, [`Self::gain`] in the posterior without the measurement at point `s` (the
    /// downdate's rows, not applied); `None` where that downdate is not positive definite.
    pub fn gains_without(&self, s: usize) -> Option<Vec<f64>> {
        let u = self.rows_for(s, -1.0)?;
        let (m, mm, base) = (self.prior.m, self.prior.m * self.prior.m, self.candidates);
        let gains = (0..self.candidates)
            .map(|c| {
                let uc = &u[c * mm..(c + 1) * mm];
                let mut cov = [0.0; 9];
                cov[..mm].copy_from_slice(&self.cov[c * mm..(c + 1) * mm]);
                subtract_outer(&mut cov, uc, uc, m, -1.0);
                let mut spread = [0.0; 9];
                for w in 0..self.workspace {
                    let mut q = [0.0; 9];
                    q[..mm].copy_from_slice(&self.cross[(c * self.workspace + w) * mm..][..mm]);
                    subtract_outer(&mut q, uc, &u[(base + w) * mm..(base + w + 1) * mm], m, -1.0);
                    accumulate_outer(&mut spread, &q, m);
                }
                self.gain_from(&cov, &spread)
            })
            .collect();
        Some(gains)
    }

    /// k_S(s, x) = k(s, x) − Σ_g sign_g V_g(s)ᵀ V_g(x) over the row groups added so far.
    fn conditioned_block(&self, s: usize, x: usize, k: &mut [f64; 9]) {
        let m = self.prior.m;
        self.prior.block(&self.points[s], &self.points[x], &mut k[..m * m]);
        let (vs, vx) = (&self.v[s], &self.v[x]);
        for (row, sign) in (0..vs.len() / m).map(|row| (row, self.signs[row / m])) {
            for r in 0..m {
                for c in 0..m {
                    k[r * m + c] -= sign * vs[row * m + r] * vx[row * m + c];
                }
            }
        }
    }

    /// The rows u_x = L_d⁻¹ k_S(s, x) of every point (m × m each), L_d L_dᵀ = sign (k_S(s, s) +
    /// sign σ²I): adding (sign 1) or removing (sign −1) the measurement at `s`.
    fn rows_for(&self, s: usize, sign: f64) -> Option<Vec<f64>> {
        let (m, mm) = (self.prior.m, self.prior.m * self.prior.m);
        let mut d = [0.0; 9];
        for k in 0..mm {
            d[k] = sign * self.cov[s * mm + k];
        }
        for r in 0..m {
            d[r * m + r] += self.prior.sigma2;
        }
        let l = cholesky(&d, m)?;
        let mut u = vec![0.0; self.points.len() * mm];
        let mut k = [0.0; 9];
        for x in 0..self.points.len() {
            self.conditioned_block(s, x, &mut k);
            u[x * mm..(x + 1) * mm].copy_from_slice(&lower_solve(&l, &k, m)[..mm]);
        }
        Some(u)
    }

    /// k_S(x, y) −= sign u_xᵀ u_y for the kept covariances, cross-covariances and spreads; the
    /// rows join V with their sign.
    fn apply(&mut self, u: Vec<f64>, sign: f64) {
        let (m, mm) = (self.prior.m, self.prior.m * self.prior.m);
        for x in 0..self.points.len() {
            let ux = &u[x * mm..(x + 1) * mm];
            self.v[x].extend_from_slice(ux);
            subtract_outer(&mut self.cov[x * mm..(x + 1) * mm], ux, ux, m, sign);
        }
        self.signs.push(sign);
        let base = self.candidates;
        for c in 0..self.candidates {
            let uc = &u[c * mm..(c + 1) * mm];
            let spread = &mut self.spread[c * mm..(c + 1) * mm];
            spread.iter_mut().for_each(|v| *v = 0.0);
            for w in 0..self.workspace {
                let uw = &u[(base + w) * mm..(base + w + 1) * mm];
                let q = &mut self.cross[(c * self.workspace + w) * mm..][..mm];
                subtract_outer(q, uc, uw, m, sign);
                accumulate_outer(spread, q, m);
            }
        }
        self.added += 1;
    }
}

/// out −= sign aᵀ b for m × m a, b (row-major).
fn subtract_outer(out: &mut [f64], a: &[f64], b: &[f64], m: usize, sign: f64) {
    for r in 0..m {
        for c in 0..m {
            out[r * m + c] -= sign * (0..m).map(|t| a[t * m + r] * b[t * m + c]).sum::<f64>();
        }
    }
}

/// out += Q Qᵀ for an m × m Q (row-major).
fn accumulate_outer(out: &mut [f64], q: &[f64], m: usize) {
    for r in 0..m {
        for s in 0..m {
            out[r * m + s] += (0..m).map(|t| q[r * m + t] * q[s * m + t]).sum::<f64>();
        }
    }
}

/// Cholesky factor (lower, row-major) of an m × m symmetric positive-definite matrix.
fn cholesky(a: &[f64], m: usize) -> Option<[f64; 9]> {
    let mut l = [0.0; 9];
    for i in 0..m {
        for j in 0..=i {
            let s = a[i * m + j] - (0..j).map(|k| l[i * m + k] * l[j * m + k]).sum::<f64>();
            if i == j {
                if !(s > 0.0) {
                    return None;
                }
                l[i * m + i] = s.sqrt();
            } else {
                l[i * m + j] = s / l[j * m + j];
            }
        }
    }
    Some(l)
}

/// L⁻¹ B for lower-triangular L and B, both m × m row-major.
fn lower_solve(l: &[f64; 9], b: &[f64], m: usize) -> [f64; 9] {
    let mut x = [0.0; 9];
    for c in 0..m {
        for r in 0..m {
            let s = b[r * m + c] - (0..r).map(|k| l[r * m + k] * x[k * m + c]).sum::<f64>();
            x[r * m + c] = s / l[r * m + r];
        }
    }
    x
}

fn transpose(a: &[f64; 9], m: usize) -> [f64; 9] {
    let mut t = [0.0; 9];
    for r in 0..m {
        for c in 0..m {
            t[c * m + r] = a[r * m + c];
        }
    }
    t
}

#[cfg(test)]
mod tests {
    use super::*;
    use faer::linalg::solvers::Solve;
    use faer::{Mat, Side};

    /// The RR arm's kernels for the small processes of these tests.
    fn small_rr_process() -> CbdHyperparameters {
        CbdHyperparameters {
            joint_axes: vec![cbd_protocol::JointKernelAxis::Periodic { b: 1.3 }; 2],
            joint_gamma: 2e-3,
            task_width: 0.8,
            task_gamma: 1e-3,
            sigma: 1e-2,
            configuration: None,
        }
    }

    /// The rank-m updates equal the posterior from one dense factorisation.
    #[test]
    fn updates_match_a_dense_posterior() {
        let rr = crate::simulate::rr::nominal();
        let h = small_rr_process();
        let q = super::super::candidates::uniform_within(&[[-3.0, 3.0], [-3.0, 3.0]], 9, 5);
        let prior = Prior::new(&h, 2);
        let points: Vec<Point> = q.chunks_exact(2).map(|x| prior.point(&rr, x, vec![0.3 * x[0], x[1].cos(), 0.1, x[0].sin()])).collect();
        let prior2 = Prior::new(&h, 2);
        let pts2: Vec<Point> = q.chunks_exact(2).map(|x| prior2.point(&rr, x, vec![0.3 * x[0], x[1].cos(), 0.1, x[0].sin()])).collect();
        let mut post = Posterior::new(prior, points, 5, 2);
        let gain = post.gain(1);
        let before = post.mean_variance(5..7);
        for s in [1, 3, 0] {
            assert!(post.add(s));
            if s == 1 {
                assert!((before - post.mean_variance(5..7) - gain).abs() < 1e-12 * before.max(1e-30) + 1e-15, "gain");
            }
        }
        // Dense: k(x,x) − k(x,S)(K_SS + σ²I)⁻¹ k(S,x) at point 8.
        let sel = [1usize, 3, 0];
        let mut blk = [0.0; 4];
        let kss = Mat::from_fn(6, 6, |i, j| {
            prior2.block(&pts2[sel[i / 2]], &pts2[sel[j / 2]], &mut blk);
            blk[(i % 2) * 2 + j % 2] + if i == j { prior2.sigma2 } else { 0.0 }
        });
        let ksx = Mat::from_fn(6, 2, |i, c| {
            prior2.block(&pts2[sel[i / 2]], &pts2[8], &mut blk);
            blk[(i % 2) * 2 + c]
        });
        let x = kss.llt(Side::Lower).unwrap().solve(&ksx);
        let reduce = ksx.transpose() * x;
        prior2.block(&pts2[8], &pts2[8], &mut blk);
        for r in 0..2 {
            for c in 0..2 {
                let dense = blk[r * 2 + c] - reduce[(r, c)];
                assert!((dense - post.cov[8 * 4 + r * 2 + c]).abs() < 1e-12, "{dense} vs {}", post.cov[8 * 4 + r * 2 + c]);
            }
        }
    }

    /// Removing a measurement inverts adding it: the covariances, cross-covariances and gains equal
    /// those of a process that never had it, and `gains_without` foresees the gains after removing.
    #[test]
    fn remove_inverts_add() {
        let rr = crate::simulate::rr::nominal();
        let h = small_rr_process();
        let q = super::super::candidates::uniform_within(&[[-3.0, 3.0], [-3.0, 3.0]], 14, 8);
        let process = || {
            let prior = Prior::new(&h, 2);
            let points = q.chunks_exact(2).map(|x| prior.point(&rr, x, vec![0.3 * x[0], x[1].cos(), 0.1, x[0].sin()])).collect();
            Posterior::new(prior, points, 8, 4)
        };
        let mut with = process();
        for s in [1, 3, 0, 12] {
            assert!(with.add(s));
        }
        let foreseen = with.gains_without(3).unwrap();
        assert!(with.remove(3));
        let mut without = process();
        for s in [1, 0, 12] {
            assert!(without.add(s));
        }
        let close = |a: f64, b: f64, scale: f64| (a - b).abs() <= 1e-9 * scale;
        let scale = without.cov.iter().fold(0.0_f64, |a, v| a.max(v.abs()));
        for (a, b) in with.cov.iter().zip(&without.cov) {
            assert!(close(*a, *b, scale), "covariance {a} vs {b}");
        }
        for (a, b) in with.cross.iter().zip(&without.cross) {
            assert!(close(*a, *b, scale), "cross-covariance {a} vs {b}");
        }
        let top = (0..8).map(|c| without.gain(c)).fold(0.0_f64, f64::max);
        for c in 0..8 {
            assert!(close(with.gain(c), without.gain(c), top), "gain {c}: {} vs {}", with.gain(c), without.gain(c));
            assert!(close(foreseen[c], without.gain(c), top), "foreseen gain {c}: {} vs {}", foreseen[c], without.gain(c));
        }
        // The removed pose's gain is its share of the criterion: re-adding it restores it.
        let before = with.criterion();
        assert!(with.add(3));
        assert!(close(before - with.criterion(), without.gain(3), top), "re-added gain");
    }
}

//! The geometric group's identifiability: the information matrix of the DH calibration's parameter
//! Jacobian over the chosen poses, its D-optimal increments and whether it is identified yet
//! (docs/DESIGN.md §13).

use faer::linalg::solvers::Solve;
use faer::{Mat, Side};

/// Below this smallest/largest eigenvalue ratio of the unit-scaled information the group is rank
/// deficient (the DH fit's own rank tolerance, `DhCalibrationOptions::rank_tolerance`, is 1e-14 on
/// converged data; before the data are in, a looser test).
const RANK_RATIO: f64 = 1e-10;

/// Tikhonov term that makes the information invertible before the group is identified.
const RIDGE: f64 = 1e-6;

/// The information M = Σ_s J_sᵀ J_s of the chosen poses, on the identifiable parameters, each
/// column scaled to unit RMS over the candidates, with (M + εI)⁻¹ kept by rank-m updates.
pub struct Identifiability {
    m: usize,
    p: usize,
    /// Per candidate: its m × p scaled Jacobian rows, row-major.
    rows: Vec<f64>,
    info: Mat<f64>,
    inverse: Mat<f64>,
    /// Mean over the evaluation set of J_eᵀ J_e (scaled): the parametric part of the predicted error.
    eval_gram: Mat<f64>,
}

impl Identifiability {
    /// `jac`: m rows per point — the candidates first (`0..candidates`, which set the column scales),
    /// the evaluation points from `eval_start` to the end — all DH parameters; `identifiable`: the
    /// columns kept.
    pub fn new(jac: &Mat<f64>, m: usize, candidates: usize, eval_start: usize, identifiable: &[usize]) -> Self {
        let p = identifiable.len();
        let total = jac.nrows() / m;
        let scale: Vec<f64> = identifiable
            .iter()
            .map(|&k| {
                let s = ((0..m * candidates).map(|i| jac[(i, k)] * jac[(i, k)]).sum::<f64>() / candidates.max(1) as f64).sqrt();
                if s > 0.0 {
                    s
                } else {
                    1.0
                }
            })
            .collect();
        let mut rows = vec![0.0; total * m * p];
        for i in 0..total * m {
            for (a, &k) in identifiable.iter().enumerate() {
                rows[i * p + a] = jac[(i, k)] / scale[a];
            }
        }
        let evals = total - eval_start;
        let mut eval_gram = Mat::zeros(p, p);
        for e in eval_start..total {
            for r in 0..m {
                let row = &rows[(e * m + r) * p..(e * m + r + 1) * p];
                for a in 0..p {
                    for b in 0..p {
                        eval_gram[(a, b)] += row[a] * row[b] / evals.max(1) as f64;
                    }
                }
            }
        }
        Identifiability {
            m,
            p,
            rows,
            info: Mat::zeros(p, p),
            inverse: Mat::from_fn(p, p, |a, b| if a == b { 1.0 / RIDGE } else { 0.0 }),
            eval_gram,
        }
    }

    /// Number of identifiable parameters.
    pub fn parameters(&self) -> usize {
        self.p
    }

    fn block(&self, point: usize) -> &[f64] {
        &self.rows[point * self.m * self.p..(point + 1) * self.m * self.p]
    }

    /// D-optimal gain of adding `point`: log det(M + JᵀJ) − log det M = log det(I + J M⁻¹ Jᵀ).
    pub fn gain(&self, point: usize) -> f64 {
        let (m, p, j) = (self.m, self.p, self.block(point));
        let mut g = Mat::<f64>::zeros(m, m);
        let mut t = vec![0.0; p];
        for r in 0..m {
            for (b, tb) in t.iter_mut().enumerate() {
                *tb = (0..p).map(|a| j[r * p + a] * self.inverse[(a, b)]).sum();
            }
            for s in 0..m {
                g[(r, s)] = (0..p).map(|b| t[b] * j[s * p + b]).sum::<f64>() + if r == s { 1.0 } else { 0.0 };
            }
        }
        match g.llt(Side::Lower) {
            Ok(l) => (0..m).map(|r| 2.0 * l.L()[(r, r)].ln()).sum(),
            Err(_) => f64::NEG_INFINITY,
        }
    }

    /// Adds `point` to the chosen poses: M += JᵀJ; (M + εI)⁻¹ by Woodbury,
    /// A⁻¹ − A⁻¹Jᵀ(I + J A⁻¹ Jᵀ)⁻¹ J A⁻¹.
    pub fn add(&mut self, point: usize) {
        let (m, p) = (self.m, self.p);
        let j = Mat::from_fn(m, p, |r, a| self.rows[(point * m + r) * p + a]);
        self.info += j.transpose() * &j;
        let aj = &self.inverse * j.transpose(); // p × m
        let s = Mat::<f64>::identity(m, m) + &j * &aj;
        if let Ok(l) = s.llt(Side::Lower) {
            let x = l.solve(aj.transpose()); // m × p
            self.inverse -= &aj * x;
        }
    }

    /// Whether the information has full rank on the identifiable parameters.
    pub fn full_rank(&self) -> bool {
        if self.p == 0 {
            return true;
        }
        match self.info.self_adjoint_eigenvalues(Side::Lower) {
            Ok(ev) => {
                let max = ev.iter().cloned().fold(0.0, f64::max);
                let min = ev.iter().cloned().fold(f64::INFINITY, f64::min);
                max > 0.0 && min > RANK_RATIO * max
            }
            Err(_) => false,
        }
    }

    /// The least-squares fit's predicted mean squared position error over the evaluation set,
    /// σ² tr(M⁻¹ mean_e J_eᵀ J_e) (its covariance σ² M⁻¹ mapped to positions); `None` while rank deficient.
    pub fn predicted_variance(&self, sigma2: f64) -> Option<f64> {
        if self.p == 0 {
            return Some(0.0);
        }
        if !self.full_rank() {
            return None;
        }
        let l = self.info.llt(Side::Lower).ok()?;
        let x = l.solve(&self.eval_gram);
        Some(sigma2 * (0..self.p).map(|a| x[(a, a)]).sum::<f64>())
    }
}

//! Which momenta the solver searches: all N·m of them, or coordinates p with P0 = S p in K_lin's
//! dominant eigenspace (the regulariser is then Sᵀ K S).

use super::{SolverMethod, DENSE_MAX_UNKNOWNS};
use crate::numeric::FIXED_SPLIT;
use crate::solver::step::DampingScale;
use crate::solver::subspace::{dominant_eigenspace, Declined, Eigenspace};
use faer::linalg::matmul::matmul;
use faer::{Accum, Mat};

/// First probe block of the eigenspace (grown while the eigenspace fills it, up to 5/8 of N·m).
const FIRST_PROBES: usize = 1280;

/// The eigenspace the solver searches, or None for all momenta.
pub(super) fn choose_basis(method: SolverMethod, k_reg: &Mat<f64>) -> Option<Eigenspace> {
    let dim = k_reg.nrows();
    match method {
        SolverMethod::Dense => None,
        // Forced: every probe the problem has, so the eigenspace is found whatever its size.
        SolverMethod::Eigenspace => dominant_eigenspace(k_reg, dim, FIXED_SPLIT).ok(),
        SolverMethod::Auto if dim <= DENSE_MAX_UNKNOWNS => None,
        SolverMethod::Auto => {
            let limit = dim * 5 / 8;
            let mut probes = FIRST_PROBES.min(limit);
            loop {
                match dominant_eigenspace(k_reg, probes, FIXED_SPLIT) {
                    Ok(e) => return Some(e),
                    Err(Declined::Full) if probes < limit => probes = (2 * probes).min(limit),
                    Err(_) => return None,
                }
            }
        }
    }
}

/// a · b on faer's fixed split.
fn product(a: &Mat<f64>, b: &Mat<f64>) -> Mat<f64> {
    let mut out = Mat::zeros(a.nrows(), b.ncols());
    matmul(out.as_mut(), Accum::Replace, a.as_ref(), b.as_ref(), 1.0, FIXED_SPLIT);
    out
}

/// The search's unknowns and their regulariser.
pub(super) struct SearchSpace {
    /// None: the unknowns are the momenta themselves.
    pub basis: Option<Eigenspace>,
    /// The regulariser's matrix in the search's coordinates: K_lin, or Sᵀ K_lin S.
    pub k_reg: Mat<f64>,
}

impl SearchSpace {
    /// `k_lin` is K_lin of all momenta; `all_momenta` keeps them all whatever `method` says.
    pub fn new(method: SolverMethod, k_lin: Mat<f64>, all_momenta: bool) -> Self {
        let basis = if all_momenta { None } else { choose_basis(method, &k_lin) };
        let k_reg = match &basis {
            Some(e) => e.projected.clone(),
            None => k_lin,
        };
        SearchSpace { basis, k_reg }
    }

    pub fn dim(&self) -> usize {
        self.k_reg.nrows()
    }

    pub fn method(&self) -> &'static str {
        if self.basis.is_some() {
            "eigenspace"
        } else {
            "dense"
        }
    }

    /// A ball in momentum space for orthonormal eigen-coordinates, Marquardt's scaling for momenta.
    pub fn damping_scale(&self) -> DampingScale {
        if self.basis.is_some() {
            DampingScale::Uniform
        } else {
            DampingScale::PerParameter
        }
    }

    /// P0 for the search's coordinates p.
    pub fn momenta_of(&self, p: &[f64]) -> Vec<f64> {
        match &self.basis {
            None => p.to_vec(),
            Some(e) => {
                let s = &e.basis;
                let mut out = vec![0.0; s.nrows()];
                for (j, pj) in p.iter().enumerate() {
                    for (o, v) in out.iter_mut().zip(s.col(j).iter()) {
                        *o += v * pj;
                    }
                }
                out
            }
        }
    }

    /// The Jacobian at P0 = 0 in the search's coordinates, from the linear response of all momenta.
    pub fn start_jacobian(&self, response: Mat<f64>) -> Mat<f64> {
        match &self.basis {
            None => response,
            Some(e) => product(&response, &e.basis),
        }
    }

    /// The linearised model's optimum for residual `r` = y − k0 (Hamiltonian laws, whose response at
    /// P0 = 0 is K_lin itself): (K_lin + σ² I)⁻¹ r; in the eigenspace p_k = (Sᵀ r)_k / (λ_k + σ²).
    pub fn linearised_solution(&self, sigma: f64, r: &[f64]) -> Option<Vec<f64>> {
        match &self.basis {
            None => crate::solver::step::solve_regularised(&self.k_reg, sigma, r, FIXED_SPLIT),
            Some(e) => Some(
                (0..self.dim())
                    .map(|k| e.basis.col(k).iter().zip(r).map(|(s, r)| s * r).sum::<f64>() / (e.projected[(k, k)] + sigma * sigma))
                    .collect(),
            ),
        }
    }
}

//! The dominant eigenspace of the regulariser K_lin, where the large-N solver searches for the momenta.
//!
//! The kernels are smooth, so K_lin's spectrum falls off faster than exponentially and, relative to
//! its largest eigenvalue, does not depend on N once the points resolve the kernels: on the RR
//! benchmark the counts of eigenvalues above 1e-12, 3e-14 and 1e-14 of the largest are 714, 855
//! and 894 for N = 1024 and N = 2304 alike. Momentum directions beyond them change neither
//! the regulariser nor (to first order) the flow, and Gauss–Newton steps that include the
//! numerically null ones overshoot and need heavy damping. So for large N the momenta are
//! P0 = S c with S the eigenvectors of K_lin above `RELATIVE_CUTOFF` of its largest eigenvalue:
//! the number of unknowns stops growing with N.
//!
//! The eigenspace comes from randomised subspace iteration (Halko, Martinsson & Tropp 2011):
//! Y = K Ω, one power step, Rayleigh–Ritz. Ω is a fixed pseudo-random matrix and every product
//! runs with faer's fixed work split, so the result does not depend on the thread count.

use crate::numeric::least_squares::QrLeastSquares;
use faer::diag::Diag;
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::evd::{self_adjoint_evd, self_adjoint_evd_scratch, ComputeEigenvectors};
use faer::linalg::matmul::matmul;
use faer::{Accum, Mat, MatRef, Par};

/// Eigenvalues of K_lin below this fraction of the largest are left out of the search space.
pub const RELATIVE_CUTOFF: f64 = 3e-14;
/// Probe columns beyond the eigenvalues kept: they make the kept ones accurate after one power step.
pub const OVERSAMPLING: usize = 256;

/// An orthonormal basis of K_lin's dominant eigenspace.
pub struct Eigenspace {
    /// dim × r, orthonormal columns: Ritz vectors, largest eigenvalue first.
    pub basis: Mat<f64>,
    /// Their Ritz values, descending.
    pub values: Vec<f64>,
    /// Sᵀ K S (r × r; diagonal to rounding), the regulariser in the basis' coordinates.
    pub projected: Mat<f64>,
    /// Probe columns used.
    pub probes: usize,
}

/// A fixed pseudo-random probe matrix with entries in [−½, ½) (splitmix64 of the entry's index).
fn probe_matrix(rows: usize, cols: usize) -> Mat<f64> {
    Mat::from_fn(rows, cols, |i, j| {
        let mut z = ((j * rows + i) as u64).wrapping_add(1).wrapping_mul(0x9e37_79b9_7f4a_7c15);
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^= z >> 31;
        (z >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    })
}

fn product(k: MatRef<'_, f64>, x: MatRef<'_, f64>, par: Par) -> Mat<f64> {
    let mut y = Mat::zeros(k.nrows(), x.ncols());
    matmul(y.as_mut(), Accum::Replace, k, x, 1.0, par);
    y
}

/// Why [`dominant_eigenspace`] found no eigenspace.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Declined {
    /// The spectrum has not fallen to the cutoff within the probes (seen before the eigen-solver):
    /// the eigenspace is not small; more probes would not be worth it.
    Flat,
    /// The kept eigenvalues fill the probe block up to the oversampling margin: more probes might do.
    Full,
}

/// Ritz pairs of symmetric `k` from `probes` probe columns (one power step): every pair whose value
/// is above `RELATIVE_CUTOFF` of the largest, unless they do not fit in the probes with the
/// oversampling margin (then the dense method is the better choice, or more probes).
pub fn dominant_eigenspace(k: &Mat<f64>, probes: usize, par: Par) -> Result<Eigenspace, Declined> {
    let dim = k.nrows();
    let probes = probes.min(dim);
    let first = QrLeastSquares::factor(product(k.as_ref(), probe_matrix(dim, probes).as_ref(), par), par);
    // Early exit, before the power step and the eigen-solver: R's diagonal of K Ω follows K's
    // spectrum roughly (within a modest factor for a fast-decaying one); if it has not fallen well
    // below the cutoff by the margin's start, the eigenspace does not fit.
    let r = first.r_diagonal();
    if probes < dim && probes > OVERSAMPLING && r[probes - OVERSAMPLING] > 100.0 * RELATIVE_CUTOFF * r[0] {
        return Err(Declined::Flat);
    }
    let mut q = first.thin_q();
    q = QrLeastSquares::factor(product(k.as_ref(), q.as_ref(), par), par).thin_q();
    let kq = product(k.as_ref(), q.as_ref(), par);
    let mut b = Mat::zeros(probes, probes);
    matmul(b.as_mut(), Accum::Replace, q.transpose(), kq.as_ref(), 1.0, par);
    let b = Mat::from_fn(probes, probes, |i, j| 0.5 * (b[(i, j)] + b[(j, i)]));
    let mut s = Diag::<f64>::zeros(probes);
    let mut v = Mat::<f64>::zeros(probes, probes);
    let mut mem = MemBuffer::new(self_adjoint_evd_scratch::<f64>(probes, ComputeEigenvectors::Yes, par, Default::default()));
    self_adjoint_evd(b.as_ref(), s.as_mut(), Some(v.as_mut()), par, MemStack::new(&mut mem), Default::default())
        .map_err(|_| Declined::Flat)?;
    // Ascending from faer; descending here.
    let values_all: Vec<f64> = (0..probes).rev().map(|i| s.column_vector()[i]).collect();
    let largest = values_all.first().copied().filter(|v| *v > 0.0).ok_or(Declined::Flat)?;
    let rank = values_all.iter().take_while(|v| **v > RELATIVE_CUTOFF * largest).count();
    if rank + OVERSAMPLING > probes && probes < dim {
        return Err(Declined::Full);
    }
    let vr = Mat::from_fn(probes, rank, |i, j| v[(i, probes - 1 - j)]);
    let basis = product(q.as_ref(), vr.as_ref(), par);
    let bv = product(b.as_ref(), vr.as_ref(), par);
    let mut projected = Mat::zeros(rank, rank);
    matmul(projected.as_mut(), Accum::Replace, vr.transpose(), bv.as_ref(), 1.0, par);
    let projected = Mat::from_fn(rank, rank, |i, j| 0.5 * (projected[(i, j)] + projected[(j, i)]));
    Ok(Eigenspace { basis, values: values_all[..rank].to_vec(), projected, probes })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A matrix with a known, fast-decaying spectrum: Q diag(10^(−k/4)) Qᵀ.
    fn known(dim: usize) -> (Mat<f64>, Vec<f64>) {
        let q = QrLeastSquares::factor(probe_matrix(dim, dim), Par::Seq).thin_q();
        let values: Vec<f64> = (0..dim).map(|k| 10f64.powf(-(k as f64) / 4.0)).collect();
        let qd = Mat::from_fn(dim, dim, |i, j| q[(i, j)] * values[j]);
        let mut k = Mat::zeros(dim, dim);
        matmul(k.as_mut(), Accum::Replace, qd.as_ref(), q.transpose(), 1.0, Par::Seq);
        (Mat::from_fn(dim, dim, |i, j| 0.5 * (k[(i, j)] + k[(j, i)])), values)
    }

    #[test]
    fn finds_the_dominant_eigenpairs() {
        let (k, values) = known(120);
        let e = dominant_eigenspace(&k, 120, Par::Seq).ok().expect("eigenspace");
        // 10^(−k/4) > 3e-14 for k ≤ 54.
        assert_eq!(e.values.len(), 55);
        for (got, want) in e.values.iter().zip(&values) {
            assert!((got - want).abs() < 1e-13, "{got} vs {want}");
        }
        // Orthonormal, and K S = S Λ.
        let ks = product(k.as_ref(), e.basis.as_ref(), Par::Seq);
        let mut worst: f64 = 0.0;
        for j in 0..e.values.len() {
            for i in 0..120 {
                worst = worst.max((ks[(i, j)] - e.values[j] * e.basis[(i, j)]).abs());
            }
            let norm: f64 = e.basis.col(j).iter().map(|v| v * v).sum();
            assert!((norm - 1.0).abs() < 1e-12);
        }
        assert!(worst < 1e-13, "{worst:e}");
        assert!((e.projected[(3, 3)] - values[3]).abs() < 1e-13 && e.projected[(3, 4)].abs() < 1e-13);
    }

    #[test]
    fn declines_when_the_eigenspace_fills_the_probes() {
        let (k, _) = known(400);
        // 55 eigenvalues are kept: 55 + 256 oversampling does not fit in 308 probes of 400 (found
        // by the eigen-solver: the spectrum at the margin's start, 1e-13, is within the early
        // exit's factor 100 of the cutoff); with 300 probes (1e-11 there) the early exit declines.
        assert_eq!(dominant_eigenspace(&k, 308, Par::Seq).err(), Some(Declined::Full));
        assert_eq!(dominant_eigenspace(&k, 300, Par::Seq).err(), Some(Declined::Flat));
        assert!(dominant_eigenspace(&k, 320, Par::Seq).is_ok());
        // A flat spectrum is declined before the eigen-solver.
        let flat = Mat::from_fn(400, 400, |i, j| if i == j { 1.0 + i as f64 / 400.0 } else { 0.0 });
        assert_eq!(dominant_eigenspace(&flat, 300, Par::Seq).err(), Some(Declined::Flat));
    }
}

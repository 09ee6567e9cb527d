//! How much a sum of kernel columns cancels: the measure behind the fit report's cancellation
//! warning (issue 25), for the kernel form's momenta and an expansion's weights alike.

use faer::Mat;

/// max_i Σ_j |K_ij p_j| / max_i |Σ_j K_ij p_j| (the fit report's `cancellation`); K may be
/// rectangular (the expansion's design matrix and weights).
pub fn cancellation_of(k: &Mat<f64>, p: &[f64]) -> f64 {
    let (mut sum, mut abs) = (vec![0.0; k.nrows()], vec![0.0; k.nrows()]);
    for (j, pj) in p.iter().enumerate() {
        for ((s, a), kij) in sum.iter_mut().zip(abs.iter_mut()).zip(k.col(j).iter()) {
            *s += kij * pj;
            *a += (kij * pj).abs();
        }
    }
    let top = |v: &[f64]| v.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    let moved = top(&sum);
    if moved > 0.0 {
        top(&abs) / moved
    } else {
        1.0
    }
}

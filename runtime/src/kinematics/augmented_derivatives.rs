//! D²k0_aug, the Hessian of the augmented kinematics of [`crate::kinematics::augmented`] (its terms
//! to second order come from `effect_terms`), beside the effects as the rigid chain's Hessian sits
//! beside it in `rigid_derivatives`.

use crate::kinematics::augmented::{deflected, effect_terms, without_effects};
use crate::kinematics::chain::{at, at2, Order};
use crate::kinematics::rigid_derivatives::NominalHessian;
use cbd_protocol::{NominalModel, MAX_JOINTS as NJ, MAX_TASK_DIM as MT};

/// D²k_rigid(q): the chain alone (the effect-free code path, [`crate::kinematics::rigid_derivatives::hessian`]).
pub fn rigid_hessian(model: &NominalModel, q: &[f64]) -> NominalHessian {
    crate::kinematics::rigid_derivatives::hessian(&without_effects(model), q)
}

/// D²k0_aug = D²k_rigid(s)[A·, A·] + Dk_rigid(s) D²δ + D²b, A = I + Dδ, `[a][e][d]`, model units.
/// (Out of line, like [`crate::kinematics::augmented::kinematics`].)
#[inline(never)]
#[cold]
pub fn hessian(model: &NominalModel, q: &[f64]) -> NominalHessian {
    let n = model.n_joints().min(q.len()).min(NJ);
    let m = model.task_dim();
    let t = effect_terms(model, &model.effects().list, q, Order::Second);
    let s = deflected(q, &t, n);
    let s = s.get(..n).unwrap_or(&[]);
    let rigid = without_effects(model);
    let jac = crate::kinematics::rigid::kinematics(&rigid, s).jacobian;
    let h = crate::kinematics::rigid_derivatives::hessian(&rigid, s);
    let mut out = [[[0.0; NJ]; NJ]; MT];
    for (((out_a, h_a), jac_a), d2b_a) in out.iter_mut().zip(h.iter()).zip(jac.iter()).zip(t.d2_b.iter()).take(m) {
        // right[i][d] = Σ_j H[a][i][j] A[j][d] = H[a][i][d] + Σ_j H[a][i][j] Dδ[j][d]
        let mut right = [[0.0; NJ]; NJ];
        for (r_i, h_ai) in right.iter_mut().zip(h_a.iter()).take(n) {
            for (d, r) in r_i.iter_mut().enumerate().take(n) {
                let mut acc = 0.0;
                for (h_aij, dd_j) in h_ai.iter().zip(t.d_delta.iter()).take(n) {
                    acc += h_aij * at(dd_j, d);
                }
                *r = at(h_ai, d) + acc;
            }
        }
        for (e, (o_e, d2b_e)) in out_a.iter_mut().zip(d2b_a.iter()).enumerate().take(n) {
            for (d, (o, d2b)) in o_e.iter_mut().zip(d2b_e.iter()).enumerate().take(n) {
                // Σ_i A[i][e] right[i][d] = right[e][d] + Σ_i Dδ[i][e] right[i][d]
                let mut acc = 0.0;
                for (dd_i, r_i) in t.d_delta.iter().zip(right.iter()).take(n) {
                    acc += at(dd_i, e) * at(r_i, d);
                }
                // + Σ_i Dk[a][i] D²δ[i][e][d]
                let mut through = 0.0;
                for (jac_ai, d2_i) in jac_a.iter().zip(t.d2_delta.iter()).take(n) {
                    through += jac_ai * at2(d2_i, e, d);
                }
                *o = at2(&right, e, d) + acc + through + d2b;
            }
        }
    }
    out
}

//! What one integration stage of a query needs from its fields, whichever form writes them (the
//! kernel form's samples or an expansion's weights): the stage-fields interface and the joint sums
//! both forms share. Apart from `query_derivatives`, so the expansion's form depends on it and
//! not on the integration that uses it.

use crate::flow::{JointField, Shape, TaskField, TaskHessian};
use crate::real::Real;
use cbd_protocol::{MAX_JOINTS as NJ, MAX_TASK_DIM as MT};

/// Values per point of the query's kernel cache: K_V, its gradient (n) and Hessian (n × n).
pub const fn kernel_row_len(n: usize) -> usize {
    1 + n + n * n
}

/// ∂w/∂ξ at the query's k, `[a][d] = ∂w_a/∂ξ_d`: the task field's explicit dependence on the query
/// configuration (the configuration term, docs/DESIGN.md §16; zero for the paper's two fields).
pub type ExplicitDerivative = [[Real; NJ]; MT];

/// `∂_d Dv(ξ)[f][e] = Σ_j u_j[f] ∂_e ∂_d K_V(ξ, x_j)`, indexed `[d][f][e]`.
pub type JointHessian = [[[Real; NJ]; NJ]; NJ];

/// v(ξ) = Σ_j K_V(ξ, x_j) u_j and Dv = Σ_j u_j ∇K_Vᵀ over one stage's samples from the kernel rows
/// (the arithmetic of [`crate::flow::joint_field`]), and (HESSIAN) ∂_d Dv[f][e] = Σ_j u_j[f] ∂_e ∂_d K_V.
/// The u_j are the n values at `offset` of every `stride` values of `coefficients`: the samples'
/// u = Jᵀ P (stride 2m + n, offset 2m) or an expansion's joint weights c_f (stride n, offset 0),
/// the rows then the joint basis ([`crate::expansion::write_joint_basis`], the same layout).
#[inline(always)]
pub(crate) fn joint_sums<S: Shape, const HESSIAN: bool>(
    shape: S,
    coefficients: &[Real],
    stride: usize,
    offset: usize,
    rows: &[Real],
) -> (JointField, JointHessian) {
    let n = shape.n();
    let mut f = JointField { v: [0.0; NJ], dv: [[0.0; NJ]; NJ] };
    let mut ddv = [[[0.0; NJ]; NJ]; NJ];
    let row_len = kernel_row_len(n);
    if n == 0 {
        return (f, ddv);
    }
    // Pairs by hand: a `zip` of two `chunks_exact` keeps a division-by-zero panic path (its length).
    let mut sample_iter = coefficients.chunks_exact(stride.max(1));
    for row in rows.chunks_exact(row_len.max(1)) {
        let Some(s) = sample_iter.next() else { break };
        let mut u = [0.0; NJ];
        for (dst, src) in u.iter_mut().zip(s.iter().skip(offset)).take(n) {
            *dst = *src;
        }
        let Some((k, rest)) = row.split_first() else { break };
        let Some((grad, hess)) = rest.split_at_checked(n) else { break };
        for ((v_a, dv_a), u_a) in f.v.iter_mut().zip(f.dv.iter_mut()).zip(u.iter()).take(n) {
            *v_a += k * u_a;
            for (dv_ab, g_b) in dv_a.iter_mut().zip(grad.iter()).take(n) {
                *dv_ab += u_a * g_b;
            }
        }
        if HESSIAN {
            // The Hessian is symmetric: row d of the cache is ∂_d ∂_e K_V for every e.
            for (ddv_d, h_d) in ddv.iter_mut().zip(hess.chunks_exact(n.max(1))).take(n) {
                for (ddv_df, u_f) in ddv_d.iter_mut().zip(u.iter()).take(n) {
                    for (o, h) in ddv_df.iter_mut().zip(h_d.iter()).take(n) {
                        *o += u_f * h;
                    }
                }
            }
        }
    }
    (f, ddv)
}

/// Where a query's fields come from at one stage, `stage` the stage's data and `rows` the query's
/// rows: the control points' samples with the kernel rows ([`KernelForm`]), or the stage's weights
/// with the joint-basis rows ([`crate::expansion::fields::ExpansionForm`]), both resolved in the
/// integration's closure as before the expansion (measured: arrangements that moved that work
/// changed the optimiser's inlining and cost the M4's f32 RR Heun × 5 evaluate up to 27 %).
pub(crate) trait StageFields {
    /// Whether the task field depends on ξ explicitly (the configuration term, §16): then the
    /// query's rates take it from [`StageFields::task_explicit`], with ∂_ξ w in the tangents.
    const EXPLICIT: bool = false;
    /// w, Dw and (HESSIAN) Σ d ∂²ψ (or Σ P ∂²K_W) at the query's current k.
    fn task<S: Shape, const HESSIAN: bool>(&self, shape: S, stage: &[Real], k: &[Real]) -> (TaskField, TaskHessian);
    /// v, Dv and (HESSIAN) ∂_d Dv at ξ.
    fn joint<S: Shape, const HESSIAN: bool>(&self, shape: S, stage: &[Real], rows: &[Real]) -> (JointField, JointHessian);
    /// w, Dw and (DERIVATIVE) ∂_ξ w at the query's current k (no second derivatives); zeros for ∂_ξ w
    /// of a field without explicit ξ-dependence.
    #[inline(always)]
    fn task_explicit<S: Shape, const DERIVATIVE: bool>(&self, shape: S, stage: &[Real], k: &[Real]) -> (TaskField, ExplicitDerivative) {
        (self.task::<_, false>(shape, stage, k).0, [[0.0; NJ]; MT])
    }
}

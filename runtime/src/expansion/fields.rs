//! The fields of one integrator stage from an expansion (docs/DESIGN.md §11): the joint field
//! v(ξ) = Σ_f φ_f(ξ) c_f with Dv and ∂_d Dv from the query's joint-basis rows (the kernel form's
//! sums over the kernel rows, [`crate::flow::query_derivatives`], with c_f for u_j), and the task
//! field w(k) = Σ_g ψ_g(k) d_g with Dw and Σ_g d_g ∂²ψ_g from the task basis at the current k.

use crate::expansion::basis_functions::for_each_task_basis_with_orders;
use crate::flow::stage_fields::{joint_sums, JointHessian, StageFields};
use crate::flow::{JointField, Shape, TaskField, TaskHessian};
use crate::kernel::{joint_kernel_exponent_n, FEATURES_PER_JOINT};
use crate::real::{exp, Real};
use cbd_protocol::{JointKernel, TaskKernel, MAX_JOINTS as NJ, MAX_TASK_DIM as MT};

/// w(k) = Σ_g ψ_g(k) d_g, `Dw[a][b] = Σ_g d_g[a] ∂_b ψ_g` and (HESSIAN) `T[a][c][b] = Σ_g d_g[a] ∂_c ∂_b ψ_g`,
/// `d` the stage's task weights (r_W × m), `orders` the coordinates' highest exponents
/// ([`crate::expansion::task_orders`]). Out of line, as the kernel form's task field.
#[inline(never)]
pub fn task_sums<S: Shape, const HESSIAN: bool>(
    shape: S,
    kernel: &TaskKernel,
    exponents: &[u8],
    orders: &[u8; MT],
    d: &[Real],
    k: &[Real],
) -> (TaskField, TaskHessian) {
    let m = shape.m();
    let mut f = TaskField { w: [0.0; MT], dw: [[0.0; MT]; MT] };
    let mut t = [[[0.0; MT]; MT]; MT];
    let mut weights = d.chunks_exact(m.max(1));
    for_each_task_basis_with_orders(kernel, exponents, orders, m, k, HESSIAN, |_, psi, grad, hess| {
        let Some(d_g) = weights.next() else { return };
        for (((w_a, dw_a), t_a), d_ga) in f.w.iter_mut().zip(f.dw.iter_mut()).zip(t.iter_mut()).zip(d_g.iter()).take(m) {
            *w_a += psi * d_ga;
            for (dw_ab, g_b) in dw_a.iter_mut().zip(grad.iter()).take(m) {
                *dw_ab += d_ga * g_b;
            }
            if HESSIAN {
                for (t_ac, h_c) in t_a.iter_mut().zip(hess.iter()).take(m) {
                    for (t_acb, h_cb) in t_ac.iter_mut().zip(h_c.iter()).take(m) {
                        *t_acb += d_ga * h_cb;
                    }
                }
            }
        }
    });
    (f, t)
}

/// Stage `stage`'s weights split into the joint part (r_V × n) and the task part (r_W × m).
#[inline(always)]
pub fn stage_weights(weights: &[Real], stage: usize, stage_len: usize, joint_len: usize) -> Option<(&[Real], &[Real])> {
    weights.get(stage * stage_len..(stage + 1) * stage_len)?.split_at_checked(joint_len)
}

/// Largest K_V(ξ, x_j)/γ over the measured configurations, exp(max_j Σ_d f_d(ξ_d − x_jd)), from the
/// query's and the configurations' kernel features: O(N n) and one exp (the meaning of
/// [`crate::Evaluation::support`] in the kernel form, where the kernel rows give it for free).
pub fn support<S: Shape>(shape: S, kernel: &JointKernel, fq: &[[Real; FEATURES_PER_JOINT]; NJ], features: &[Real]) -> Real {
    let n = shape.n();
    if n == 0 {
        return 0.0;
    }
    let (mut pairs, _) = features.as_chunks::<FEATURES_PER_JOINT>();
    let mut best = Real::NEG_INFINITY;
    while let Some((fxj, rest)) = pairs.split_at_checked(n) {
        pairs = rest;
        let e = joint_kernel_exponent_n(kernel, n, fq, fxj);
        if e > best {
            best = e;
        }
    }
    exp(best)
}

/// An expansion's fields: a stage's data are its weights, c (r_V × n) then d (r_W × m), rounded
/// once to [`Real`] at load; the rows the query's joint basis ([`crate::expansion::write_joint_basis`]).
pub(crate) struct ExpansionForm<'r> {
    pub task_kernel: TaskKernel,
    pub exponents: &'r [u8],
    /// The task coordinates' highest exponents ([`crate::expansion::task_orders`]).
    pub orders: [u8; MT],
    /// r_V n: where d starts in a stage's weights.
    pub joint_len: usize,
}

impl StageFields for ExpansionForm<'_> {
    #[inline(always)]
    fn task<S: Shape, const HESSIAN: bool>(&self, shape: S, weights: &[Real], k: &[Real]) -> (TaskField, TaskHessian) {
        let d = weights.get(self.joint_len..).unwrap_or(&[]);
        task_sums::<_, HESSIAN>(shape, &self.task_kernel, self.exponents, &self.orders, d, k)
    }
    #[inline(always)]
    fn joint<S: Shape, const HESSIAN: bool>(&self, shape: S, weights: &[Real], rows: &[Real]) -> (JointField, JointHessian) {
        let c = weights.get(..self.joint_len).unwrap_or(&[]);
        joint_sums::<_, HESSIAN>(shape, c, shape.n(), 0, rows)
    }
}

/// v(x) = Σ_f φ_f(x) c_f from joint-basis rows (the velocity of the joint flow φ).
#[inline(always)]
pub fn joint_velocity<S: Shape>(shape: S, c: &[Real], rows: &[Real]) -> [Real; NJ] {
    joint_sums::<_, false>(shape, c, shape.n(), 0, rows).0.v
}

/// w(y) = Σ_g ψ_g(y) d_g (the velocity of the task flow ψ), `orders` as in [`task_sums`].
#[inline(always)]
pub fn task_velocity<S: Shape>(shape: S, kernel: &TaskKernel, exponents: &[u8], orders: &[u8; MT], d: &[Real], y: &[Real]) -> [Real; MT] {
    task_sums::<_, false>(shape, kernel, exponents, orders, d, y).0.w
}

//! The tangent of the discrete flow: ∂k_i(1)/∂P0 for all initial momenta at once.
//!
//! All m·N tangent directions are propagated together through the same fixed-step scheme
//! as the primal (the runtime's `integrate`), so the result is the exact derivative of the
//! discrete model. Each stage's linearised right-hand side is a handful of N×N kernel matrices
//! times N×D blocks of tangents (GEMMs on faer), plus row scalings.
//!
//! Tangent layout: column-major, rows component-major (row = c·N + i for state component c of
//! point i: c < m is k, then J row-major, then P), one column per direction.

use super::primal::{ControlPoints, PrimalFlow};
use cbd_protocol::MAX_JOINTS;
use cbd_runtime::internals::flow::Dims;
use cbd_runtime::internals::kernel::{joint_kernel_from_features, read_features};
use faer::linalg::matmul::matmul;
use faer::{Accum, Mat, MatMut, MatRef, Par};

/// The kernel matrices and per-point quantities the linearised dynamics need at one stage.
struct StageLinearisation {
    kw: Mat<f64>,
    /// G_b[i, j] = ∂K_W(k_i, k_j)/∂k_i[b].
    g: Vec<Mat<f64>>,
    /// H_bc[i, j] = ∂²K_W/∂k_i[b]∂k_i[c], index b·m + c.
    h: Vec<Mat<f64>>,
    /// Per point: P_a (m), J_ad (m·n), Dw_ab (m²), v_d (n), Dv_de (n²), div, T_abc (m³).
    p: Vec<Vec<f64>>,
    jac: Vec<Vec<f64>>,
    dw: Vec<Vec<f64>>,
    v: Vec<Vec<f64>>,
    dv: Vec<Vec<f64>>,
    div: Vec<f64>,
    t: Vec<Vec<f64>>,
}

/// K_V and its gradients ∂_e K_V (with respect to the first argument); constant along the flow.
struct JointKernelMatrices {
    kv: Mat<f64>,
    gv: Vec<Mat<f64>>,
}

fn joint_kernel_matrices(cp: &ControlPoints) -> JointKernelMatrices {
    let (n, count) = (cp.dims.n, cp.len());
    let mut kv = Mat::zeros(count, count);
    let mut gv: Vec<Mat<f64>> = (0..n).map(|_| Mat::zeros(count, count)).collect();
    let mut grad = [0.0; MAX_JOINTS];
    let features = |i: usize| read_features(&cp.features, n, i);
    for j in 0..count {
        let fj = features(j);
        for i in 0..count {
            // Bit-identical to `joint_kernel` of the configurations (which computes the features first).
            let value = joint_kernel_from_features(&cp.joint_kernel, &features(i), &fj, &mut grad);
            kv[(i, j)] = value;
            for e in 0..n {
                gv[e][(i, j)] = grad[e];
            }
        }
    }
    JointKernelMatrices { kv, gv }
}

/// With `positions_only` (the last stage) the second derivatives H of K_W are not formed: only
/// the k rows of that stage's rates are needed, and they do not involve H.
fn linearise_stage(cp: &ControlPoints, jk: &JointKernelMatrices, state: &[f64], positions_only: bool) -> StageLinearisation {
    let Dims { m, n } = cp.dims;
    let (len, count) = (cp.dims.state_len(), cp.len());
    let inv_a2 = 1.0 / (cp.task_kernel.width * cp.task_kernel.width);
    let at = |i: usize| &state[i * len..(i + 1) * len];
    let per_point = |k: usize| -> Vec<Vec<f64>> { (0..k).map(|_| vec![0.0; count]).collect() };
    let (mut p, mut jac, mut u) = (per_point(m), per_point(m * n), per_point(n));
    for i in 0..count {
        let s = at(i);
        for a in 0..m {
            p[a][i] = s[m + m * n + a];
            for d in 0..n {
                jac[a * n + d][i] = s[m + a * n + d];
            }
        }
        for d in 0..n {
            u[d][i] = (0..m).map(|a| s[m + a * n + d] * s[m + m * n + a]).sum();
        }
    }
    let mut kw = Mat::zeros(count, count);
    let mut g: Vec<Mat<f64>> = (0..m).map(|_| Mat::zeros(count, count)).collect();
    let mut h: Vec<Mat<f64>> = if positions_only { Vec::new() } else { (0..m * m).map(|_| Mat::zeros(count, count)).collect() };
    let (mut dw, mut t) = (per_point(m * m), per_point(m * m * m));
    for j in 0..count {
        let kj = &at(j)[..m];
        for i in 0..count {
            let ki = &at(i)[..m];
            let mut e = [0.0; 3];
            let mut r2 = 0.0;
            for c in 0..m {
                e[c] = ki[c] - kj[c];
                r2 += e[c] * e[c];
            }
            let k = (-0.5 * r2 * inv_a2).exp();
            kw[(i, j)] = k;
            for b in 0..m {
                let gb = -k * e[b] * inv_a2;
                g[b][(i, j)] = gb;
                for a in 0..m {
                    dw[a * m + b][i] += p[a][j] * gb;
                }
                if positions_only {
                    continue;
                }
                for c in 0..m {
                    let hbc = k * (e[b] * e[c] * inv_a2 * inv_a2 - if b == c { inv_a2 } else { 0.0 });
                    h[b * m + c][(i, j)] = hbc;
                    for a in 0..m {
                        t[(a * m + b) * m + c][i] += p[a][j] * hbc;
                    }
                }
            }
        }
    }
    let (mut v, mut dv) = (per_point(n), per_point(n * n));
    // Column by column (contiguous in the column-major matrices); every v[d][i] and dv[..][i]
    // still sums over j in order.
    for j in 0..count {
        let kv_j = jk.kv.col(j);
        for d in 0..n {
            let u_dj = u[d][j];
            for (v_i, k) in v[d].iter_mut().zip(kv_j.iter()) {
                *v_i += k * u_dj;
            }
            for e in 0..n {
                for (dv_i, g) in dv[d * n + e].iter_mut().zip(jk.gv[e].col(j).iter()) {
                    *dv_i += u_dj * g;
                }
            }
        }
    }
    let mut div: Vec<f64> = (0..count).map(|i| (0..n).map(|d| dv[d * n + d][i]).sum()).collect();
    if !cp.law.has_divergence() {
        div.iter_mut().for_each(|x| *x = 0.0);
    }
    StageLinearisation { kw, g, h, p, jac, dw, v, dv, div, t }
}

/// out += sign · diag(scale) · input (row scaling), column by column.
fn add_row_scaled(mut out: MatMut<'_, f64>, scale: &[f64], input: MatRef<'_, f64>, sign: f64) {
    for col in 0..out.ncols() {
        for (i, s) in scale.iter().enumerate() {
            out[(i, col)] += sign * s * input[(i, col)];
        }
    }
}

/// out (+)= alpha · lhs · rhs. A GEMM, except when rhs is mostly zeros (the first stage's tangent is
/// the identity in the momentum rows and zero elsewhere): then only its nonzeros' columns of lhs are
/// combined, O(nnz · rows) instead of O(rows · inner · cols).
fn gemm(mut out: MatMut<'_, f64>, accum: Accum, lhs: MatRef<'_, f64>, rhs: MatRef<'_, f64>, alpha: f64) {
    let nonzeros = (0..rhs.ncols()).map(|c| rhs.col(c).iter().filter(|v| **v != 0.0).count()).sum::<usize>();
    if nonzeros * 8 > rhs.nrows() * rhs.ncols() {
        matmul(out, accum, lhs, rhs, alpha, Par::Seq);
        return;
    }
    if matches!(accum, Accum::Replace) {
        out.fill(0.0);
    }
    for col in 0..rhs.ncols() {
        for (r, &v) in rhs.col(col).iter().enumerate() {
            if v != 0.0 {
                let scale = alpha * v;
                for (o, l) in out.as_mut().col_mut(col).iter_mut().zip(lhs.col(r).iter()) {
                    *o += scale * l;
                }
            }
        }
    }
}

/// δDw_ab (index a·m + b) and δDv_de (index d·n + e) blocks of one stage's tangent rates.
type FieldTangents = (Vec<Mat<f64>>, Vec<Mat<f64>>);

/// Linearised right-hand side of the control-point dynamics for one column chunk. With
/// `positions_only` only the k rows are formed (the last stage: its J and P rates reach nothing
/// that is read), which skips the δDw and δDv products, two thirds of the GEMMs; otherwise the
/// δDw and δDv blocks are returned too.
fn control_point_tangent_rates(
    cp: &ControlPoints,
    jk: &JointKernelMatrices,
    lin: &StageLinearisation,
    tan: MatRef<'_, f64>,
    mut out: MatMut<'_, f64>,
    positions_only: bool,
) -> Option<FieldTangents> {
    let Dims { m, n } = cp.dims;
    let count = cp.len();
    let cols = tan.ncols();
    let blk = |c: usize| tan.subrows(c * count, count);
    let k_of = |a: usize| a;
    let j_of = |a: usize, d: usize| m + a * n + d;
    let p_of = |a: usize| m + m * n + a;
    let zeros = |k: usize| -> Vec<Mat<f64>> { (0..k).map(|_| Mat::zeros(count, cols)).collect() };

    // δu_d = Σ_a (P_a δJ_ad + J_ad δP_a)
    let mut du = zeros(n);
    for d in 0..n {
        for a in 0..m {
            add_row_scaled(du[d].as_mut(), &lin.p[a], blk(j_of(a, d)), 1.0);
            add_row_scaled(du[d].as_mut(), &lin.jac[a * n + d], blk(p_of(a)), 1.0);
        }
    }
    // S_ac = diag(P_a) δk_c
    let mut s = zeros(m * m);
    for a in 0..m {
        for c in 0..m {
            add_row_scaled(s[a * m + c].as_mut(), &lin.p[a], blk(k_of(c)), 1.0);
        }
    }
    // δw_a = K_W δP_a − Σ_b G_b S_ab + Σ_b diag(Dw_ab) δk_b
    let mut dw = zeros(m);
    for a in 0..m {
        gemm(dw[a].as_mut(), Accum::Replace, lin.kw.as_ref(), blk(p_of(a)), 1.0);
        for b in 0..m {
            gemm(dw[a].as_mut(), Accum::Add, lin.g[b].as_ref(), s[a * m + b].as_ref(), -1.0);
            add_row_scaled(dw[a].as_mut(), &lin.dw[a * m + b], blk(k_of(b)), 1.0);
        }
    }
    // δv_d = K_V δu_d
    let mut dvv = zeros(n);
    for d in 0..n {
        gemm(dvv[d].as_mut(), Accum::Replace, jk.kv.as_ref(), du[d].as_ref(), 1.0);
    }
    out.fill(0.0);
    // δ(dk_a) = δw_a − Σ_d (diag(v_d) δJ_ad + diag(J_ad) δv_d)
    for a in 0..m {
        let mut o = out.as_mut().subrows_mut(k_of(a) * count, count);
        o.copy_from(dw[a].as_ref());
        for d in 0..n {
            add_row_scaled(o.as_mut(), &lin.v[d], blk(j_of(a, d)), -1.0);
            add_row_scaled(o.as_mut(), &lin.jac[a * n + d], dvv[d].as_ref(), -1.0);
        }
    }
    if positions_only {
        return None;
    }
    // δDw_ab = G_b δP_a + Σ_c (diag(T_abc) δk_c − H_bc S_ac)
    let mut ddw = zeros(m * m);
    for a in 0..m {
        for b in 0..m {
            let o = &mut ddw[a * m + b];
            gemm(o.as_mut(), Accum::Replace, lin.g[b].as_ref(), blk(p_of(a)), 1.0);
            for c in 0..m {
                add_row_scaled(o.as_mut(), &lin.t[(a * m + b) * m + c], blk(k_of(c)), 1.0);
                gemm(o.as_mut(), Accum::Add, lin.h[b * m + c].as_ref(), s[a * m + c].as_ref(), -1.0);
            }
        }
    }
    // δDv_de = ∂_e K_V δu_d
    let mut ddv = zeros(n * n);
    for d in 0..n {
        for e in 0..n {
            gemm(ddv[d * n + e].as_mut(), Accum::Replace, jk.gv[e].as_ref(), du[d].as_ref(), 1.0);
        }
    }
    // δ(dJ_ad) = Σ_c (J_cd δDw_ac + Dw_ac δJ_cd) − Σ_e (Dv_ed δJ_ae + J_ae δDv_ed)
    for a in 0..m {
        for d in 0..n {
            let mut o = out.as_mut().subrows_mut(j_of(a, d) * count, count);
            for c in 0..m {
                add_row_scaled(o.as_mut(), &lin.jac[c * n + d], ddw[a * m + c].as_ref(), 1.0);
                add_row_scaled(o.as_mut(), &lin.dw[a * m + c], blk(j_of(c, d)), 1.0);
            }
            for e in 0..n {
                add_row_scaled(o.as_mut(), &lin.dv[e * n + d], blk(j_of(a, e)), -1.0);
                add_row_scaled(o.as_mut(), &lin.jac[a * n + e], ddv[e * n + d].as_ref(), -1.0);
            }
        }
    }
    momentum_rates(cp, lin, tan, &ddw, &ddv, out);
    Some((ddw, ddv))
}

/// The momentum rows of the tangent rates, δ(dP_a) = −Σ_c (P_c δDw_ca + Dw_ca δP_c) − (P_a δdiv + div δP_a),
/// from the stage's δDw and δDv blocks (`ddv` indexed d·n + e; only d = e is read).
fn momentum_rates(
    cp: &ControlPoints,
    lin: &StageLinearisation,
    tan: MatRef<'_, f64>,
    ddw: &[Mat<f64>],
    ddv: &[Mat<f64>],
    mut out: MatMut<'_, f64>,
) {
    let Dims { m, n } = cp.dims;
    let count = cp.len();
    let blk = |c: usize| tan.subrows(c * count, count);
    let p_of = |a: usize| m + m * n + a;
    let with_div = cp.law.has_divergence();
    for a in 0..m {
        let mut o = out.as_mut().subrows_mut(p_of(a) * count, count);
        for c in 0..m {
            add_row_scaled(o.as_mut(), &lin.p[c], ddw[c * m + a].as_ref(), -1.0);
            add_row_scaled(o.as_mut(), &lin.dw[c * m + a], blk(p_of(c)), -1.0);
        }
        if with_div {
            for d in 0..n {
                add_row_scaled(o.as_mut(), &lin.p[a], ddv[d * n + d].as_ref(), -1.0);
            }
            add_row_scaled(o.as_mut(), &lin.div, blk(p_of(a)), -1.0);
        }
    }
}

/// Tangent columns per chunk: bounds the working set (about 20 blocks of N × columns per chunk in
/// flight) while keeping the products GEMM-shaped. The split depends on N only, never on threads.
const CHUNK_COLUMNS: usize = 256;

/// ∂k1(x_i)/∂P0 of the discrete flow: an (N·m) × (N·m) matrix, rows i·m + a (output point and
/// coordinate), columns j·m + b (momentum of point j, coordinate b). Internal units.
pub fn position_jacobian(cp: &ControlPoints, flow: &PrimalFlow, threads: usize) -> Mat<f64> {
    super::with_threads(threads, || position_jacobian_in_pool(cp, flow))
}

/// `position_jacobian` on the current rayon pool: column chunks run in parallel.
pub fn position_jacobian_in_pool(cp: &ControlPoints, flow: &PrimalFlow) -> Mat<f64> {
    let m = cp.dims.m;
    // Initial tangent of direction j·m + b: δP_{j,b} = 1.
    propagate(cp, flow, cp.len() * m, |dir, p_rows| p_rows[(dir % m) * cp.len() + dir / m] = 1.0, None)
}

/// ∂k1/∂P0 · D for momentum directions D ((N·m) × r, rows j·m + b like P0): the (N·m) × r matrix
/// of the discrete flow's derivatives along D's columns, on the current rayon pool. Costs r/(N·m)
/// of [`position_jacobian_in_pool`]'s GEMMs after the first stage (the identity's sparsity makes
/// that one cheap there).
pub fn position_jacobian_along(cp: &ControlPoints, flow: &PrimalFlow, directions: MatRef<'_, f64>) -> Mat<f64> {
    let (m, count) = (cp.dims.m, cp.len());
    assert_eq!(directions.nrows(), count * m, "direction length");
    propagate(cp, flow, directions.ncols(), |dir, p| fill_direction(directions, m, count, dir, p), None)
}

/// The first stage's tangent rates along fixed directions as far as they do not depend on P0: the
/// first stage of every scheme is evaluated at the initial state, whose k and J do not depend on
/// P0, with the initial tangent (δk, δJ, δP) = (0, 0, D). Its k and J rows and its δDw, δDv blocks
/// are therefore the same at every P0 (12 of the 20 N × N GEMMs of a Gauss–Newton Jacobian for
/// Euler × 2); only the momentum rows are formed again. The values are the uncached ones exactly.
pub struct TangentAlong {
    directions: Mat<f64>,
    /// Per column chunk: the first stage's rates and its δDw, δDv blocks (None: one-stage scheme).
    first: Vec<Option<(Mat<f64>, FieldTangents)>>,
}

impl TangentAlong {
    /// Forms the first stage's P0-independent part for `directions` ((N·m) × r, rows j·m + b), on
    /// the current rayon pool.
    pub fn new(cp: &ControlPoints, directions: Mat<f64>) -> Self {
        use rayon::prelude::*;
        let (m, count) = (cp.dims.m, cp.len());
        assert_eq!(directions.nrows(), count * m, "direction length");
        let single_stage = cp.integrator.stage_count() == 1;
        let first = if single_stage {
            vec![None; chunk_bounds(directions.ncols()).len()]
        } else {
            let jk = joint_kernel_matrices(cp);
            // The linearisation at the initial state with P0 = 0: its kernel matrices and J are those
            // of any P0; the P0-dependent vectors (P, Dw, v, Dv, div, T) multiply zero blocks.
            let lin = linearise_stage(cp, &jk, &cp.initial, false);
            let rows = count * cp.dims.state_len();
            chunk_bounds(directions.ncols())
                .par_iter()
                .map(|&(d0, d1)| {
                    let tan = initial_tangent(cp, d0, d1, |dir, p| fill_direction(directions.as_ref(), m, count, dir, p));
                    let mut out = Mat::zeros(rows, d1 - d0);
                    let tan = MatRef::from_column_major_slice(&tan, rows, d1 - d0);
                    let fields = control_point_tangent_rates(cp, &jk, &lin, tan, out.as_mut(), false);
                    fields.map(|f| (out, f))
                })
                .collect()
        };
        TangentAlong { directions, first }
    }

    /// ∂k1/∂P0 · D at `flow`'s momenta: (N·m) × r, as [`position_jacobian_along`].
    pub fn jacobian(&self, cp: &ControlPoints, flow: &PrimalFlow) -> Mat<f64> {
        let (m, count) = (cp.dims.m, cp.len());
        propagate(cp, flow, self.directions.ncols(), |dir, p| fill_direction(self.directions.as_ref(), m, count, dir, p), Some(&self.first))
    }
}

fn fill_direction(directions: MatRef<'_, f64>, m: usize, count: usize, dir: usize, p_rows: &mut [f64]) {
    for (r, v) in directions.col(dir).iter().enumerate() {
        p_rows[(r % m) * count + r / m] = *v;
    }
}

/// Column chunks of `directions` tangent directions; depends on their count only, never on threads.
fn chunk_bounds(directions: usize) -> Vec<(usize, usize)> {
    let chunks = directions.div_ceil(CHUNK_COLUMNS).max(2);
    (0..chunks).map(|c| (c * directions / chunks, (c + 1) * directions / chunks)).collect()
}

/// The initial tangent of directions d0..d1 (column-major, N·state_len rows component-major): zero k and J
/// rows, the momentum rows that `init(dir, p_rows)` writes (row b·N + j).
fn initial_tangent(cp: &ControlPoints, d0: usize, d1: usize, init: impl Fn(usize, &mut [f64])) -> Vec<f64> {
    let dims = cp.dims;
    let (m, count) = (dims.m, cp.len());
    let rows = count * dims.state_len();
    let p_start = (m + m * dims.n) * count;
    let mut tan = vec![0.0; rows * (d1 - d0)];
    for dir in d0..d1 {
        let col = &mut tan[(dir - d0) * rows..(dir - d0 + 1) * rows];
        init(dir, &mut col[p_start..p_start + m * count]);
    }
    tan
}

/// Propagates `directions` tangents (initial tangents from `init`, see [`initial_tangent`]) through
/// the scheme and returns the positions of t = 1, rows i·m + a. With `first`, the first stage's
/// P0-independent part comes from [`TangentAlong`]'s cache.
fn propagate(
    cp: &ControlPoints,
    flow: &PrimalFlow,
    directions: usize,
    init: impl Fn(usize, &mut [f64]) + Sync,
    first: Option<&[Option<(Mat<f64>, FieldTangents)>]>,
) -> Mat<f64> {
    use rayon::prelude::*;
    let dims = cp.dims;
    let (m, count, len) = (dims.m, cp.len(), dims.state_len());
    let jk = joint_kernel_matrices(cp);
    let stage_len = count * len;
    let stage_count = flow.stage_states.len() / stage_len;
    let stages: Vec<StageLinearisation> =
        flow.stage_states.chunks_exact(stage_len).enumerate().map(|(k, y)| linearise_stage(cp, &jk, y, k + 1 == stage_count)).collect();
    let rows = count * len;
    let bounds = chunk_bounds(directions);
    // Each chunk returns only the position rows it ends with (m·N × columns), not its whole state.
    let run_chunk = |(chunk, &(d0, d1)): (usize, &(usize, usize))| -> Vec<f64> {
        let cols = d1 - d0;
        let cached = first.and_then(|f| f[chunk].as_ref());
        let mut tan = initial_tangent(cp, d0, d1, &init);
        let mut scratch = vec![0.0; cbd_runtime::internals::integrate::scratch_len(tan.len())];
        let result: Result<(), ()> = cbd_runtime::internals::integrate::integrate(
            cp.integrator.method,
            cp.integrator.steps,
            &mut tan,
            &mut scratch,
            |stage, y, out| {
                let y = MatRef::from_column_major_slice(y, rows, cols);
                let mut out = MatMut::from_column_major_slice_mut(out, rows, cols);
                match cached {
                    Some((rates, (ddw, ddv))) if stage == 0 => {
                        out.copy_from(rates);
                        out.as_mut().subrows_mut((m + m * dims.n) * count, m * count).fill(0.0);
                        momentum_rates(cp, &stages[0], y, ddw, ddv, out);
                    }
                    _ => {
                        control_point_tangent_rates(cp, &jk, &stages[stage], y, out, stage + 1 == stages.len());
                    }
                }
                Ok(())
            },
        );
        let _ = result;
        drop(scratch);
        let mut positions = vec![0.0; m * count * cols];
        for c in 0..cols {
            positions[c * m * count..(c + 1) * m * count].copy_from_slice(&tan[c * rows..c * rows + m * count]);
        }
        positions
    };
    let results: Vec<Vec<f64>> = bounds.par_iter().enumerate().map(run_chunk).collect();
    let mut jac = Mat::zeros(count * m, directions);
    for (&(d0, d1), tan) in bounds.iter().zip(&results) {
        for dir in d0..d1 {
            let col = &tan[(dir - d0) * m * count..(dir - d0 + 1) * m * count];
            for i in 0..count {
                for a in 0..m {
                    jac[(i * m + a, dir)] = col[a * count + i];
                }
            }
        }
    }
    jac
}

#[cfg(test)]
mod tests;

//! The last stage's reduced rates ([`query_rates`] with `last`) against the full rates: the primal
//! and δk rates bit for bit, whatever the rows' second derivatives hold; integrated with every
//! scheme, the same k(1), J(1) and δk(1) (the exact Jacobian) as integrating with full rates.

extern crate std;
use super::*;
use crate::expansion::fields::ExpansionForm;
use crate::expansion::{joint_row_len, write_joint_basis};
use crate::flow::Fixed;
use crate::kernel::{joint_features, write_features};
use cbd_protocol::{IntegratorMethod, JointKernelAxis};
use heapless::Vec as HVec;

/// Values in [−0.5, 0.5) from a fixed sequence.
fn fill(out: &mut [Real], seed: u32) {
    let mut s = seed;
    for v in out.iter_mut() {
        s = s.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
        *v = ((s >> 8) as f64 / 16_777_216.0 - 0.5) as Real;
    }
}

fn joint_kernel(n: usize) -> JointKernel {
    let mut axes = HVec::new();
    for d in 0..n {
        let axis =
            if d % 3 == 1 { JointKernelAxis::Gaussian { width: 0.9 } } else { JointKernelAxis::Periodic { b: 0.7 + 0.1 * d as f64 } };
        axes.push(axis).unwrap();
    }
    JointKernel { gamma: 1.5, axes }
}

const MAX_ROWS: usize = 40;
/// The longest query state with tangents: (k, J) and n tangents of it.
const Y: usize = (MT + MT * NJ) * (1 + NJ);
const ROWS_LEN: usize = MAX_ROWS * (1 + NJ + NJ * NJ);

/// An expansion's stage data and rows for shape (m, n): r_V joint functions of mixed orders, r_W
/// task functions (total degree ≤ 3), pseudo-random weights; the rows' Hessian part written.
struct Expansion {
    codes: [u8; MAX_ROWS * NJ],
    exponents: [u8; MAX_ROWS * MT],
    r_v: usize,
    r_w: usize,
    weights: [Real; MAX_ROWS * (NJ + MT)],
    rows: [Real; ROWS_LEN],
}

fn expansion(m: usize, n: usize, x: &[f64]) -> Expansion {
    let mut e = Expansion {
        codes: [0; MAX_ROWS * NJ],
        exponents: [0; MAX_ROWS * MT],
        r_v: 24,
        r_w: 0,
        weights: [0.0; MAX_ROWS * (NJ + MT)],
        rows: [0.0; ROWS_LEN],
    };
    for f in 0..e.r_v {
        for d in 0..n {
            e.codes[f * n + d] = ((f * (d + 3) + d) % 9) as u8;
        }
    }
    'outer: for total in 0..=3usize {
        for g in 0..MT.pow(4) {
            let alpha: [usize; MT] = core::array::from_fn(|c| (g / 4usize.pow(c as u32)) % 4);
            if alpha.iter().skip(m).any(|a| *a != 0) || alpha.iter().sum::<usize>() != total {
                continue;
            }
            if e.r_w == MAX_ROWS {
                break 'outer;
            }
            for c in 0..m {
                e.exponents[e.r_w * m + c] = alpha[c] as u8;
            }
            e.r_w += 1;
        }
    }
    fill(&mut e.weights[..e.r_v * n + e.r_w * m], 0x5eed + m as u32 * 7 + n as u32);
    write_joint_basis(&joint_kernel(n), &e.codes[..e.r_v * n], n, x, &mut e.rows[..e.r_v * joint_row_len(n)], true);
    e
}

/// A kernel form's stage data (N samples k, P, u) and kernel rows (with Hessians) at x.
fn kernel_form(m: usize, n: usize, x: &[f64]) -> ([Real; MAX_ROWS * (2 * MT + NJ)], usize, [Real; ROWS_LEN]) {
    let count = 30;
    let kernel = joint_kernel(n);
    let mut points = [0.0; MAX_ROWS * NJ];
    for (i, p) in points.iter_mut().enumerate().take(count * n) {
        *p = libm::sin(1.7 * i as f64) * 2.5;
    }
    let mut features = [0.0 as Real; MAX_ROWS * NJ * FEATURES_PER_JOINT];
    write_features(&kernel, n, &points[..count * n], &mut features[..count * n * FEATURES_PER_JOINT]);
    let mut fq = [[0.0; FEATURES_PER_JOINT]; NJ];
    joint_features(&kernel, x, &mut fq);
    let mut rows = [0.0; ROWS_LEN];
    write_kernel_rows(
        Dims { m, n },
        &kernel,
        &fq,
        &features[..count * n * FEATURES_PER_JOINT],
        &mut rows[..count * kernel_row_len(n)],
        true,
    );
    let mut samples = [0.0; MAX_ROWS * (2 * MT + NJ)];
    let len = count * (2 * m + n);
    fill(&mut samples[..len], 0xfeed + m as u32);
    (samples, len, rows)
}

/// Integrates a query state (k, J and n tangents, pseudo-random) with `method` × `steps`, the last
/// stage reduced (`reduce`) or not; returns the final state.
fn integrate_query<S: Shape, F: StageFields>(
    shape: S,
    form: &F,
    stage_data: &[Real],
    rows: &[Real],
    method: IntegratorMethod,
    steps: u16,
    reduce: bool,
) -> [Real; Y] {
    let dims = shape.dims();
    let len = query_tangent_len(dims);
    let mut y = [0.0; Y];
    fill(&mut y[..len], 0xabc + len as u32);
    let mut scratch = [0.0; 3 * Y];
    let last = method.stages() * steps as usize - 1;
    crate::integrate::integrate_checked(method, steps, &mut y[..len], &mut scratch, (), |stage, s, out| {
        query_rates(shape, form, stage_data, rows, s, out, reduce && stage == last).ok_or(())
    })
    .unwrap();
    y
}

/// Final states with the last stage reduced and not: k, J and every δk bit for bit; δJ(1) differs
/// (nothing reads it) only when the last stage was reduced.
fn assert_same_outputs(dims: Dims, reduced: &[Real], full: &[Real]) {
    let ql = dims.query_len();
    let bits = |v: &[Real]| v.iter().map(|x| x.to_bits()).collect::<std::vec::Vec<_>>();
    assert_eq!(bits(&reduced[..ql]), bits(&full[..ql]), "k(1), J(1)");
    for d in 0..dims.n {
        let t = ql * (1 + d);
        assert_eq!(bits(&reduced[t..t + dims.m]), bits(&full[t..t + dims.m]), "δk_{d}(1)");
    }
    assert!(full.iter().all(|v| v.is_finite()) && reduced[..ql].iter().any(|v| *v != 0.0));
}

fn check_shape<S: Shape>(shape: S) {
    let dims = shape.dims();
    let (m, n) = (dims.m, dims.n);
    let x = [0.4, -1.1, 2.0, 0.3, -0.6, 1.2];
    let x = &x[..n];
    let schemes = [(IntegratorMethod::Euler, 1), (IntegratorMethod::Euler, 2), (IntegratorMethod::Heun, 2), (IntegratorMethod::Rk4, 1)];

    let e = expansion(m, n, x);
    let exponents = &e.exponents[..e.r_w * m];
    let form = ExpansionForm {
        task_kernel: TaskKernel { width: 1.3 },
        exponents,
        orders: crate::expansion::task_orders(exponents, m),
        joint_len: e.r_v * n,
    };
    let stage = &e.weights[..e.r_v * n + e.r_w * m];
    let rows = &e.rows[..e.r_v * joint_row_len(n)];
    let (samples, len, kernel_rows) = kernel_form(m, n, x);
    let kform = KernelForm { task_kernel: TaskKernel { width: 0.8 } };
    for (method, steps) in schemes {
        assert_same_outputs(
            dims,
            &integrate_query(shape, &form, stage, rows, method, steps, true),
            &integrate_query(shape, &form, stage, rows, method, steps, false),
        );
        assert_same_outputs(
            dims,
            &integrate_query(shape, &kform, &samples[..len], &kernel_rows, method, steps, true),
            &integrate_query(shape, &kform, &samples[..len], &kernel_rows, method, steps, false),
        );
    }

    // One stage's rates: the reduced ones never read the rows' second derivatives and write δJ' = 0.
    let q = dims.query_len();
    let mut state = [0.0; Y];
    fill(&mut state[..q * (1 + n)], 0x77);
    let mut poisoned = e.rows;
    for row in poisoned.chunks_exact_mut(joint_row_len(n)).take(e.r_v) {
        row[1 + n..].fill(Real::NAN);
    }
    let (mut full, mut reduced) = ([0.0; Y], [1.0; Y]);
    query_rates(shape, &form, stage, rows, &state[..q * (1 + n)], &mut full[..q * (1 + n)], false).unwrap();
    query_rates(shape, &form, stage, &poisoned[..rows.len()], &state[..q * (1 + n)], &mut reduced[..q * (1 + n)], true).unwrap();
    assert_same_outputs(dims, &reduced, &full);
    for d in 0..n {
        let t = q * (1 + d);
        assert!(reduced[t + m..t + q].iter().all(|v| *v == 0.0), "δJ_{d}' of the last stage");
    }
}

#[test]
fn the_last_stage_without_second_derivatives_gives_the_same_bits() {
    check_shape(Fixed::<2, 2>);
    check_shape(Dims { m: 2, n: 2 });
    check_shape(Fixed::<3, 6>);
    check_shape(Dims { m: 3, n: 4 });
    check_shape(Dims { m: 1, n: 1 });
}

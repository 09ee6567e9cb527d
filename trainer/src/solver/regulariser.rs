//! The quadratic part of energy (16) and the linearised model around P0 = 0.

use crate::flow::ControlPoints;
use cbd_protocol::MAX_JOINTS;
use cbd_runtime::kernel::{joint_kernel_from_features, read_features, task_kernel};
use faer::Mat;

/// Blocks (J_i J_jᵀ) K_V(x_i, x_j) and K_W(k0_i, k0_j) I of the initial state, combined with signs:
/// `joint_sign` · Dk0 K_V Dk0ᵀ + K_W. Rows and columns i·m + a.
fn combined(cp: &ControlPoints, joint_sign: f64) -> Mat<f64> {
    let dims = cp.dims;
    let (m, n, len, count) = (dims.m, dims.n, dims.state_len(), cp.len());
    let s = |i: usize| &cp.initial[i * len..(i + 1) * len];
    let mut out = Mat::zeros(count * m, count * m);
    let mut g = [0.0; MAX_JOINTS];
    let mut gw = [0.0; 3];
    let features = |i: usize| read_features(&cp.features, n, i);
    // Column by column (contiguous); K_V from the feature table, bit-identical to `joint_kernel`.
    for j in 0..count {
        let fj = features(j);
        for i in 0..count {
            let kv = joint_kernel_from_features(&cp.joint_kernel, &features(i), &fj, &mut g);
            let mut diff = [0.0; 3];
            for c in 0..m {
                diff[c] = s(i)[c] - s(j)[c];
            }
            let kw = task_kernel(&cp.task_kernel, &diff, m, &mut gw);
            for b in 0..m {
                for a in 0..m {
                    let jj: f64 = (0..n).map(|d| s(i)[m + a * n + d] * s(j)[m + b * n + d]).sum();
                    out[(i * m + a, j * m + b)] = joint_sign * kv * jj + if a == b { kw } else { 0.0 };
                }
            }
        }
    }
    out
}

/// K_lin = Dk0 K_V Dk0ᵀ + K_W: energy (16)'s regulariser is ½ P0ᵀ K_lin P0 (`cp.joint_kernel`
/// carries the field's sign s, so s · s K_V = K_V).
pub fn regulariser_matrix(cp: &ControlPoints) -> Mat<f64> {
    combined(cp, cp.law.joint_field_sign())
}

/// ∂k1/∂P0 at P0 = 0: K_W − s Dk0 K_V Dk0ᵀ (the flow moves k by w − J v, v = s K_V Jᵀ P): K_lin
/// itself for the Hamiltonian laws (s = −1).
pub fn linear_response(cp: &ControlPoints) -> Mat<f64> {
    combined(cp, -1.0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::flow::tangent::position_jacobian;
    use cbd_protocol::*;

    #[test]
    fn linear_response_is_the_tangent_at_zero() {
        let nominal = crate::simulate::rr::nominal();
        let points = crate::simulate::configurations(crate::simulate::Sampling::Uniform { count: 9, seed: 5 }, 2);
        for law in [MomentumLaw::WithDivergence, MomentumLaw::Hamiltonian] {
            let cp = ControlPoints::new(
                &nominal,
                &Normalisation::IDENTITY,
                points.clone(),
                JointKernel { gamma: 8.0, axes: heapless::Vec::from_slice(&[JointKernelAxis::Periodic { b: 1.0 }; 2]).unwrap() },
                TaskKernel { width: 1.0 },
                law,
                Integrator { method: IntegratorMethod::Heun, steps: 4 },
            );
            let zero = vec![0.0; 18];
            let jac = position_jacobian(&cp, &cp.integrate(&zero).unwrap(), 1);
            let lin = linear_response(&cp);
            let reg = regulariser_matrix(&cp);
            let worst =
                (0..18).flat_map(|r| (0..18).map(move |c| (r, c))).fold(0.0f64, |w, (r, c)| w.max((jac[(r, c)] - lin[(r, c)]).abs()));
            assert!(worst < 1e-12, "{law:?}: {worst:e}");
            // The regulariser is K_lin whatever the sign; the Hamiltonian law's response is K_lin itself.
            let gap = (0..18).flat_map(|r| (0..18).map(move |c| (r, c))).fold(0.0f64, |w, (r, c)| w.max((reg[(r, c)] - lin[(r, c)]).abs()));
            let expect_equal = law == MomentumLaw::Hamiltonian;
            assert_eq!(gap < 1e-12, expect_equal, "{law:?}: |K_lin − response| = {gap:e}");
        }
    }
}

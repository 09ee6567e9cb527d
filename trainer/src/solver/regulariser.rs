//! The quadratic part of energy (16) and the linearised model around P0 = 0.

use crate::flow::ControlPoints;
use cbd_protocol::{ConfigurationKernel, JointKernel, TaskKernel, MAX_JOINTS, MAX_TASK_DIM};
use cbd_runtime::internals::kernel::{joint_kernel, joint_kernel_from_features, read_features, task_kernel};
use faer::Mat;

/// J_i J_jᵀ (m × m, row-major) of two m × n Jacobians stored row-major: Σ_d J_i[a, d] J_j[b, d].
pub(crate) fn jacobian_outer(ji: &[f64], jj: &[f64], m: usize, n: usize, out: &mut [f64]) {
    for a in 0..m {
        for b in 0..m {
            out[a * m + b] = (0..n).map(|d| ji[a * n + d] * jj[b * n + d]).sum();
        }
    }
}

/// K_lin = γ_V Dk0 K̃_V Dk0ᵀ + γ_W K̃_W I + γ_C K̃_C I (docs/DESIGN.md §3, §16), the one assembly:
/// block (i, j) is (γ_V k_V) J_i J_jᵀ + (γ_W k_W + γ_C k_C) I, rows and columns i·m + a, with
/// `pair(i, j, jj)` giving (k_V, k_W, k_C) of rows i ≥ j and writing J_i J_jᵀ into `jj` (k_C and
/// γ_C zero without the configuration term); the upper blocks are the lower ones mirrored (every
/// kernel here is symmetric to the bit).
pub(crate) fn assemble_k_lin(
    count: usize,
    m: usize,
    gamma_v: f64,
    gamma_w: f64,
    gamma_c: f64,
    mut pair: impl FnMut(usize, usize, &mut [f64]) -> (f64, f64, f64),
) -> Mat<f64> {
    let mut k = Mat::<f64>::zeros(count * m, count * m);
    let mut jj = [0.0; MAX_TASK_DIM * MAX_TASK_DIM];
    for i in 0..count {
        for j in 0..=i {
            let (kv, kw, kc) = pair(i, j, &mut jj[..m * m]);
            // Without the term the diagonal is γ_W k_W exactly as before (no + 0 · k_C rounding).
            let iso = if gamma_c == 0.0 { gamma_w * kw } else { gamma_w * kw + gamma_c * kc };
            for a in 0..m {
                for b in 0..m {
                    let v = gamma_v * kv * jj[a * m + b] + if a == b { iso } else { 0.0 };
                    k[(i * m + a, j * m + b)] = v;
                    k[(j * m + b, i * m + a)] = v;
                }
            }
        }
    }
    k
}

/// `joint_sign` · Dk0 K_V Dk0ᵀ + K_W (+ γ_C K̃_Q K̃_X I with the configuration term) at the control
/// points' initial state, the kernels the runtime's (`joint_kernel_from_features`, `joint_kernel`,
/// `task_kernel`; K_V carries γ and the flow's sign).
fn combined(cp: &ControlPoints, joint_sign: f64, configuration: Option<&ConfigurationKernel>) -> Mat<f64> {
    let dims = cp.dims;
    let (m, n, len) = (dims.m, dims.n, dims.state_len());
    let s = |i: usize| &cp.initial[i * len..(i + 1) * len];
    let features = |i: usize| read_features(&cp.features, n, i);
    let (mut g, mut gw) = ([0.0; MAX_JOINTS], [0.0; MAX_TASK_DIM]);
    // K̃_Q with unit amplitude in the configuration kernel's axes, and its task factor (1 when flat).
    let config = configuration.map(|c| (JointKernel { gamma: 1.0, axes: c.axes.clone() }, c.task_width.map(|width| TaskKernel { width })));
    let point = |i: usize| &cp.points[i * n..(i + 1) * n];
    assemble_k_lin(cp.len(), m, joint_sign, 1.0, configuration.map_or(0.0, |c| c.gamma), |i, j, jj| {
        let kv = joint_kernel_from_features(&cp.joint_kernel, &features(i), &features(j), &mut g);
        let mut diff = [0.0; MAX_TASK_DIM];
        for c in 0..m {
            diff[c] = s(i)[c] - s(j)[c];
        }
        jacobian_outer(&s(i)[m..m + m * n], &s(j)[m..m + m * n], m, n, jj);
        let kc = match &config {
            // c_j(ξ)/γ_C = exp(Σ_d f_d(ξ_d − q_jd)) · exp(−|k0(ξ) − k0(q_j)|²/2a_C²) (§16).
            Some((kq, kx)) => {
                joint_kernel(kq, point(i), point(j), &mut g) * kx.as_ref().map_or(1.0, |kx| task_kernel(kx, &diff, m, &mut gw))
            }
            None => 0.0,
        };
        (kv, task_kernel(&cp.task_kernel, &diff, m, &mut gw), kc)
    })
}

/// K_lin with the configuration-dependent task term (docs/DESIGN.md §16): Dk0 K_V Dk0ᵀ + K_W I +
/// γ_C K̃_Q(q_i, q_j) K̃_X(k0_i, k0_j) I, the regulariser and (Hamiltonian law, Euler × 1) the linear
/// response of the model whose blob carries `configuration`.
pub fn k_lin_with_configuration(cp: &ControlPoints, configuration: &ConfigurationKernel) -> Mat<f64> {
    combined(cp, cp.law.joint_field_sign(), Some(configuration))
}

/// K_lin = Dk0 K_V Dk0ᵀ + K_W: energy (16)'s regulariser is ½ P0ᵀ K_lin P0 (`cp.joint_kernel`
/// carries the field's sign s, so s · s K_V = K_V).
pub fn regulariser_matrix(cp: &ControlPoints) -> Mat<f64> {
    combined(cp, cp.law.joint_field_sign(), None)
}

/// ∂k1/∂P0 at P0 = 0: K_W − s Dk0 K_V Dk0ᵀ (the flow moves k by w − J v, v = s K_V Jᵀ P): K_lin
/// itself for the Hamiltonian laws (s = −1).
pub fn linear_response(cp: &ControlPoints) -> Mat<f64> {
    combined(cp, -1.0, None)
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

    /// The one K_lin assembly is the runtime's kernel evaluation to the last bit: every entry equals
    /// s·K_V(x_i, x_j) (J_i J_jᵀ)_ab + δ_ab K_W(k0_i, k0_j) with `joint_kernel` and `task_kernel`
    /// called directly, the mirrored upper blocks included.
    #[test]
    fn k_lin_is_the_runtimes_kernel_evaluation_to_the_last_bit() {
        use cbd_runtime::internals::kernel::joint_kernel;
        use cbd_runtime::internals::kinematics::forward_kinematics;
        let robot = crate::simulate::six_joint::SixJointRobot::ur5_like(3);
        let (count, n, m) = (7, 6, 3);
        let points = crate::simulate::six_joint::random_configurations(count, 4);
        let norm = Normalisation { task_offset: [0.1, -0.2, 0.3], task_scale: 0.8 };
        let axes = [0.3, 1.1, 0.7, 2.0, 0.05, 0.4].map(|b| JointKernelAxis::Periodic { b });
        let kernel = JointKernel { gamma: 0.7, axes: heapless::Vec::from_slice(&axes).unwrap() };
        for law in [MomentumLaw::Hamiltonian, MomentumLaw::WithDivergence] {
            let integrator = Integrator { method: IntegratorMethod::Euler, steps: 1 };
            let cp = ControlPoints::new(&robot.nominal, &norm, points.clone(), kernel.clone(), TaskKernel { width: 1.3 }, law, integrator);
            let k = regulariser_matrix(&cp);
            let (mut g, mut gw) = ([0.0; MAX_JOINTS], [0.0; MAX_TASK_DIM]);
            for i in 0..count {
                for j in 0..count {
                    let (xi, xj) = (&points[i * n..(i + 1) * n], &points[j * n..(j + 1) * n]);
                    let (ki, kj) = (
                        forward_kinematics(&robot.nominal, xi).normalised(&norm),
                        forward_kinematics(&robot.nominal, xj).normalised(&norm),
                    );
                    let kv = joint_kernel(&cp.joint_kernel, xi, xj, &mut g);
                    let mut diff = [0.0; MAX_TASK_DIM];
                    for c in 0..m {
                        diff[c] = ki.position[c] - kj.position[c];
                    }
                    let kw = task_kernel(&cp.task_kernel, &diff, m, &mut gw);
                    for a in 0..m {
                        for b in 0..m {
                            let jj: f64 = (0..n).map(|d| ki.jacobian[a][d] * kj.jacobian[b][d]).sum();
                            let expected = law.joint_field_sign() * kv * jj + if a == b { kw } else { 0.0 };
                            assert_eq!(k[(i * m + a, j * m + b)].to_bits(), expected.to_bits(), "{law:?}: rows {i} {j}, block ({a}, {b})");
                        }
                    }
                }
            }
        }
    }
}

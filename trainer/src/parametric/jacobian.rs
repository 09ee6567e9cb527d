//! The identification Jacobian ∂k/∂p of a DH chain's tool position with respect to its parameter
//! vector (`nominal::dh_parameters`), analytic from the one DH frame walk (`dh_walk`): a joint's
//! θ, d are a rotation about / translation along z, its a, α a translation along / rotation about
//! x, so ∂k/∂(rotation about u through o) = u × (k − o) and ∂k/∂(translation along u) = u.

use super::residuals::residuals;
use crate::data::Measurements;
use crate::nominal::dh_parameters::apply_parameters;
use cbd_protocol::DhChain;
use faer::Mat;

/// ∂k/∂(DH rows, base translation, tool translation) at the chain's current parameters, into
/// `jac` (`data.task_dim` rows per measurement); the base-rotation columns are left for the caller.
pub(super) fn analytic_jacobian(chain: &DhChain, data: &Measurements, jac: &mut Mat<f64>) {
    use crate::nominal::{cross, sub};
    use cbd_protocol::DhConvention;
    use cbd_runtime::internals::kinematics::rigid::dh_walk;
    let (n, m) = (chain.joints.len(), data.task_dim);
    let column = |r: &[[f64; 3]; 3], c: usize| [r[0][c], r[1][c], r[2][c]];
    let model = cbd_protocol::NominalModel::DhChain(chain.clone());
    for row in 0..data.len() {
        let walk = dh_walk(chain, data.joints(row));
        // The row's tool point (row mod m_p, docs/DESIGN.md §12): y = o_tool + R_tool p_j.
        let pj = model.tool_point(row % model.tool_point_count()).unwrap_or([0.0; 3]);
        let p = if pj == [0.0; 3] {
            walk.tool
        } else {
            let r = &walk.tool_rotation;
            std::array::from_fn(|a| walk.tool[a] + (r[a][0] * pj[0] + r[a][1] * pj[1] + r[a][2] * pj[2]))
        };
        // Frame i (0 = base, i = after joint i): its rotation's column c and its origin.
        let axis = |i: usize, c: usize| if i == 0 { column(&walk.start_rotation, c) } else { column(&walk.end_rotations[i - 1], c) };
        let origin = |i: usize| if i == 0 { walk.start } else { walk.ends[i - 1] };
        let mut put = |col: usize, v: [f64; 3]| {
            for c in 0..m {
                jac[(m * row + c, col)] = v[c];
            }
        };
        for i in 1..=n {
            let base_col = 4 * (i - 1);
            match chain.convention {
                // Rz(θ) Tz(d) about/along z_{i−1}; Tx(a) Rx(α) along/about x_i through o_i.
                DhConvention::Standard => {
                    put(base_col, axis(i, 0));
                    put(base_col + 1, cross(axis(i, 0), sub(p, origin(i))));
                    put(base_col + 2, axis(i - 1, 2));
                    put(base_col + 3, cross(axis(i - 1, 2), sub(p, origin(i - 1))));
                }
                // Rx(α) Tx(a) about/along x_{i−1} through o_{i−1}; Rz(θ) Tz(d) about/along z_i.
                DhConvention::Modified => {
                    put(base_col, axis(i - 1, 0));
                    put(base_col + 1, cross(axis(i - 1, 0), sub(p, origin(i - 1))));
                    put(base_col + 2, axis(i, 2));
                    put(base_col + 3, cross(axis(i, 2), sub(p, origin(i))));
                }
            }
        }
        let o = 4 * n;
        for k in 0..3 {
            let mut e = [0.0; 3];
            e[k] = 1.0;
            put(o + k, e);
            // Tool translation is expressed in the last joint frame.
            put(o + 6 + k, axis(n, k));
        }
    }
}

/// The Jacobian of the residuals at parameter changes `p` from `chain0`: analytic columns for the
/// DH rows, base translation and tool translation; central differences for the base and tool
/// rotations (their axis-angle parametrisations), with `scratch` for the two residual vectors.
pub(super) fn jacobian_at(chain0: &DhChain, p: &[f64], data: &Measurements, jac: &mut Mat<f64>, scratch: (&mut [f64], &mut [f64])) {
    let (rp, rm) = scratch;
    let n = chain0.joints.len();
    analytic_jacobian(&apply_parameters(chain0, p), data, jac);
    for k in (4 * n + 3..4 * n + 6).chain(4 * n + 9..p.len()) {
        let h = 1e-6;
        let mut q = p.to_vec();
        q[k] = p[k] + h;
        residuals(&apply_parameters(chain0, &q), data, rp);
        q[k] = p[k] - h;
        residuals(&apply_parameters(chain0, &q), data, rm);
        for i in 0..jac.nrows() {
            jac[(i, k)] = (rp[i] - rm[i]) / (2.0 * h);
        }
    }
}

/// The identification Jacobian ∂k/∂p of `chain` at its own parameters (p = 0), every parameter of
/// `nominal::dh_parameters`, at each row of `joints` (row-major): `m` rows per configuration, the
/// first `m` task coordinates. Effects are not part of it: pass the rigid chain and, for a model
/// with joint deflections, the deflected joints q + δ(q).
pub fn geometric_jacobian(chain: &DhChain, joints: &[f64], m: usize) -> Mat<f64> {
    let n = chain.joints.len().max(1);
    let count = joints.len() / n;
    let data = Measurements {
        n_joints: n,
        task_dim: m,
        points_per_pose: 1,
        joints: joints[..count * n].to_vec(),
        positions: vec![0.0; count * m],
        order: crate::data::RowOrder::Measured,
    };
    let np = crate::nominal::dh_parameters::parameter_count_for(chain);
    let mut jac = Mat::zeros(m * count, np);
    let (mut rp, mut rm) = (vec![0.0; m * count], vec![0.0; m * count]);
    jacobian_at(chain, &vec![0.0; np], &data, &mut jac, (&mut rp, &mut rm));
    jac
}

/// Sets the Jacobian columns of parameters that do not move (out of the plane, frozen) to zero.
pub(super) fn zero_columns(jac: &mut Mat<f64>, columns: &[usize]) {
    for &k in columns {
        for i in 0..jac.nrows() {
            jac[(i, k)] = 0.0;
        }
    }
}

/// The column norms of `jac`, floored: a parameter with almost no effect must not take huge steps
/// (a null direction drifting to 1e10 rad would ruin the arithmetic).
pub(super) fn column_scales(jac: &Mat<f64>, colnorm: &mut [f64]) {
    for (k, c) in colnorm.iter_mut().enumerate() {
        *c = (0..jac.nrows()).map(|i| jac[(i, k)] * jac[(i, k)]).sum::<f64>().sqrt();
    }
    let floor = 1e-6 * colnorm.iter().cloned().fold(0.0, f64::max);
    for c in colnorm.iter_mut() {
        *c = c.max(floor).max(f64::MIN_POSITIVE);
    }
}

#[cfg(test)]
mod tests {
    use super::super::tests::{sample, ur5_like};
    use super::*;
    use crate::nominal::dh_parameters::{parameter_count, parameter_names};
    use cbd_protocol::{DhConvention, NominalModel};

    #[test]
    fn analytic_jacobian_matches_central_differences() {
        for conv in [DhConvention::Standard, DhConvention::Modified] {
            let mut p: Vec<f64> = (0..parameter_count(6)).map(|k| 0.01 * ((k * 37 % 11) as f64 - 5.0)).collect();
            p[27] = 0.02; // base rotation too
            let chain = apply_parameters(&ur5_like(conv), &p);
            let data = sample(&NominalModel::DhChain(chain.clone()), 5, 9);
            let np = parameter_count(6);
            let mut jac = Mat::<f64>::zeros(15, np);
            analytic_jacobian(&chain, &data, &mut jac);
            let (mut rp, mut rm) = (vec![0.0; 15], vec![0.0; 15]);
            for k in (0..np).filter(|k| !(27..30).contains(k)) {
                let h = 1e-5;
                let mut q = p.clone();
                q[k] += h;
                residuals(&apply_parameters(&ur5_like(conv), &q), &data, &mut rp);
                q[k] -= 2.0 * h;
                residuals(&apply_parameters(&ur5_like(conv), &q), &data, &mut rm);
                for i in 0..15 {
                    let fd = (rp[i] - rm[i]) / (2.0 * h);
                    assert!(
                        (fd - jac[(i, k)]).abs() < 1e-5 * (1.0 + fd.abs()),
                        "{conv:?} {} row {i}: fd {fd} analytic {}",
                        parameter_names(6)[k],
                        jac[(i, k)]
                    );
                }
            }
        }
    }
}

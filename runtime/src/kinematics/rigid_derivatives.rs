//! D²k0 of the rigid chain alone (effects aside): the second derivatives beside the first
//! ([`crate::kinematics::rigid`]). `query_derivatives::nominal_hessian` dispatches here for effect-free
//! models, and the effects' Hessian builds on it.

use crate::kinematics::spatial::{cross, sub};
use cbd_protocol::{DhChain, JointKind, NominalModel, MAX_JOINTS as NJ, MAX_TASK_DIM as MT};

/// Second derivatives of the nominal model: `h[a][e][d] = ∂²k0_a / ∂x_e ∂x_d`, model units.
pub type NominalHessian = [[[f64; NJ]; NJ]; MT];

/// D²k0(x) of the chain, ignoring any effects the model carries.
pub fn hessian(model: &NominalModel, x: &[f64]) -> NominalHessian {
    let mut h = [[[0.0; NJ]; NJ]; MT];
    write_hessian(model, x, &mut h);
    h
}

/// [`hessian`] written into `h`, which must hold zeros (the query's path: no copy of the array).
pub fn write_hessian(model: &NominalModel, x: &[f64], h: &mut NominalHessian) {
    match model {
        // ∂²y/∂x_e∂x_d = Σ_{k ≥ max(d, e)} −l_k (cos θ_k, sin θ_k)
        NominalModel::PlanarChain { lengths, .. } => {
            let mut theta = 0.0;
            for (k, (l, xk)) in lengths.iter().zip(x).enumerate() {
                theta += xk;
                let term = [-l * libm::cos(theta), -l * libm::sin(theta)];
                for (h_a, t) in h.iter_mut().zip(term.iter()) {
                    for row in h_a.iter_mut().take(k + 1) {
                        for v in row.iter_mut().take(k + 1) {
                            *v += t;
                        }
                    }
                }
            }
        }
        NominalModel::DhChain(chain) => dh_hessian(chain, x, h),
    }
}

// Column j of Dk0 is z_j × (p − o_j) (revolute) or z_j (prismatic). Its derivative with respect
// to joint i: the axes and origins of joints after i turn with joint i, and p moves with every joint.
fn dh_hessian(chain: &DhChain, x: &[f64], h: &mut NominalHessian) {
    let (axes, origins, p) = crate::kinematics::rigid::dh_frames(chain, x);
    let n = chain.joints.len().min(x.len());
    for (j, (joint_j, (z_j, o_j))) in chain.joints.iter().zip(axes.iter().zip(origins.iter())).enumerate().take(n) {
        for (i, (joint_i, (z_i, o_i))) in chain.joints.iter().zip(axes.iter().zip(origins.iter())).enumerate().take(n) {
            let value = match (joint_j.kind, joint_i.kind) {
                // i ≤ j: z_j and (p − o_j) both rotate about z_i; i > j: only p moves.
                (JointKind::Revolute, JointKind::Revolute) if i <= j => cross(*z_i, cross(*z_j, sub(p, *o_j))),
                (JointKind::Revolute, JointKind::Revolute) => cross(*z_j, cross(*z_i, sub(p, *o_i))),
                // A prismatic joint before j translates p and o_j alike.
                (JointKind::Revolute, JointKind::Prismatic) if i < j => [0.0; 3],
                (JointKind::Revolute, JointKind::Prismatic) => cross(*z_j, *z_i),
                (JointKind::Prismatic, JointKind::Revolute) if i < j => cross(*z_i, *z_j),
                (JointKind::Prismatic, _) => [0.0; 3],
            };
            for (h_a, v) in h.iter_mut().zip(value.iter()) {
                if let Some(slot) = h_a.get_mut(i).and_then(|row| row.get_mut(j)) {
                    *slot = *v;
                }
            }
        }
    }
}

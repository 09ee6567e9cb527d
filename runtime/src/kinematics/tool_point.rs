//! Several tool points per pose (issue 26 item 1): tool point j of a DH chain is the origin of the
//! tool frame moved by its offset p_j, so the point's k0, Dk0 and D²k0 are those of the same chain
//! with the tool translation t + R p_j (R, t the `tool` transform) — every existing kinematics path
//! (rigid chain, effects, Hessians) evaluates it unchanged.

use crate::kinematics::tool_frame::{fit_frame, FrameFit, FrameVelocity};
use crate::kinematics::{forward_kinematics, Kinematics};
use cbd_protocol::{NominalModel, MAX_JOINTS, MAX_TASK_DIM, MAX_TOOL_POINTS};

/// `model` with its tool frame's origin at tool point `j` (no tool points left), or `None` when
/// `j` ≥ [`NominalModel::tool_point_count`].
pub fn at_tool_point(model: &NominalModel, j: usize) -> Option<NominalModel> {
    let p = model.tool_point(j)?;
    let mut out = model.clone();
    if let NominalModel::DhChain(chain) = &mut out {
        // t_j = t + R p_j (R row-major).
        let r = chain.tool.rotation;
        for (row, t) in r.chunks_exact(3).zip(chain.tool.translation.iter_mut()) {
            let rp: f64 = row.iter().zip(p.iter()).map(|(a, b)| a * b).sum();
            *t += rp;
        }
        chain.tool_points.clear();
    }
    Some(out)
}

/// Calls `f` with the nominal model whose tool point is `j`: `model` itself when it names no tool
/// points (`j = 0`, the same bits as before format 6, no copy), otherwise [`at_tool_point`]'s copy.
/// `None` when `j` is out of range.
#[inline]
pub fn with_tool_point<R>(model: &NominalModel, j: usize, f: impl FnOnce(&NominalModel) -> R) -> Option<R> {
    if model.tool_points().is_empty() {
        return (j == 0).then(|| f(model));
    }
    at_tool_point(model, j).map(|m| f(&m))
}

/// k0 and Dk0 of tool point `j` at joints `x` ([`forward_kinematics`] is `j = 0` of a model
/// without tool points). Out of range `j`: every value NaN (a caller's finiteness check refuses it).
pub fn forward_kinematics_at(model: &NominalModel, x: &[f64], j: usize) -> Kinematics {
    with_tool_point(model, j, |m| forward_kinematics(m, x))
        .unwrap_or(Kinematics { position: [f64::NAN; MAX_TASK_DIM], jacobian: [[f64::NAN; MAX_JOINTS]; MAX_TASK_DIM] })
}

/// The nominal tool frame at joints `x`: the least-squares frame of the nominal tool points k0_j(x)
/// ([`crate::kinematics::tool_frame::fit_frame`]; for a rigid chain exactly the DH walk's tool frame)
/// and its 6 × n Jacobian (rows: the origin's linear velocity, the angular velocity). `None` when
/// the tool points do not determine an orientation or a value is not finite.
pub fn nominal_tool_frame(model: &NominalModel, x: &[f64]) -> Option<(FrameFit, [[f64; MAX_JOINTS]; 6])> {
    let count = model.tool_point_count();
    let mut nominal = [[0.0; 3]; MAX_TOOL_POINTS];
    let mut points = [[0.0; 3]; MAX_TOOL_POINTS];
    let mut jacobians = [[[0.0; MAX_JOINTS]; MAX_TASK_DIM]; MAX_TOOL_POINTS];
    for (j, ((p, y), jac)) in nominal.iter_mut().zip(points.iter_mut()).zip(jacobians.iter_mut()).enumerate().take(count) {
        *p = model.tool_point(j)?;
        let k = forward_kinematics_at(model, x, j);
        *y = k.position;
        *jac = k.jacobian;
    }
    let (nominal, points) = (nominal.get(..count)?, points.get(..count)?);
    let fit = fit_frame(nominal, points)?;
    let velocity = FrameVelocity::new(&fit, nominal, points)?;
    let mut out = [[0.0; MAX_JOINTS]; 6];
    for d in 0..x.len().min(MAX_JOINTS) {
        let mut column = [[0.0; 3]; MAX_TOOL_POINTS];
        for (dy, jac) in column.iter_mut().zip(jacobians.iter()).take(count) {
            for (v, row) in dy.iter_mut().zip(jac.iter()) {
                *v = row.get(d).copied().unwrap_or(0.0);
            }
        }
        let (dt, omega) = velocity.apply(column.get(..count)?)?;
        for (row, v) in out.iter_mut().zip(dt.iter().chain(omega.iter())) {
            *row.get_mut(d)? = *v;
        }
    }
    out.iter().flatten().all(|v| v.is_finite()).then_some((fit, out))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::flow::query_derivatives::nominal_hessian;
    use cbd_protocol::{ur5, Effect, Effects};

    fn chain_with(points: &[[f64; 3]], effects: bool) -> NominalModel {
        let mut c = ur5::chain();
        // A rotated, offset tool frame, so that t + R p is not t + p.
        let (s, co) = (libm::sin(0.4), libm::cos(0.4));
        c.tool.rotation = [co, -s, 0.0, s * 0.6, co * 0.6, -0.8, s * 0.8, co * 0.8, 0.6];
        c.tool.translation = [3.0, -2.0, 31.0];
        c.tool_points = heapless::Vec::from_slice(points).unwrap();
        if effects {
            c.effects =
                Effects { list: heapless::Vec::from_slice(&[Effect::LinkBending { link: 5, compliance: 1e-5 }]).unwrap(), ..Effects::NONE };
        }
        NominalModel::DhChain(c)
    }

    const Q: [f64; 6] = [0.3, -1.1, 1.4, 0.2, -0.7, 2.1];

    #[test]
    fn a_model_without_tool_points_is_point_zero_bit_for_bit() {
        let m = chain_with(&[], false);
        assert_eq!(forward_kinematics_at(&m, &Q, 0), forward_kinematics(&m, &Q));
        assert!(forward_kinematics_at(&m, &Q, 1).position[0].is_nan());
    }

    #[test]
    fn a_tool_point_is_the_tool_frame_origin_moved_by_its_offset() {
        let p = [[0.0, 0.0, 0.0], [100.0, 0.0, 0.0], [0.0, 100.0, 20.0]];
        for effects in [false, true] {
            let m = chain_with(&p, effects);
            let walk = match &chain_with(&[], effects) {
                NominalModel::DhChain(c) => crate::kinematics::rigid::dh_walk(c, &Q),
                _ => unreachable!(),
            };
            assert_eq!(forward_kinematics_at(&m, &Q, 0), forward_kinematics(&chain_with(&[], effects), &Q));
            for (j, pj) in p.iter().enumerate() {
                let k = forward_kinematics_at(&m, &Q, j);
                if !effects {
                    // y_j = o_tool + R_tool p_j
                    for (a, row) in walk.tool_rotation.iter().enumerate() {
                        let y = walk.tool[a] + row.iter().zip(pj).map(|(r, v)| r * v).sum::<f64>();
                        assert!((k.position[a] - y).abs() < 1e-9, "point {j} coordinate {a}");
                    }
                }
                // Jacobian and Hessian against central differences.
                let h = 1e-5;
                let hess = with_tool_point(&m, j, |n| nominal_hessian(n, &Q)).unwrap();
                for d in 0..6 {
                    let (mut qa, mut qb) = (Q, Q);
                    qa[d] += h;
                    qb[d] -= h;
                    let (ka, kb) = (forward_kinematics_at(&m, &qa, j), forward_kinematics_at(&m, &qb, j));
                    for a in 0..3 {
                        let fd = (ka.position[a] - kb.position[a]) / (2.0 * h);
                        assert!(
                            (fd - k.jacobian[a][d]).abs() < 1e-5 * (1.0 + fd.abs()),
                            "J point {j} [{a}][{d}]: {fd} vs {}",
                            k.jacobian[a][d]
                        );
                        for e in 0..6 {
                            let fd2 = (ka.jacobian[a][e] - kb.jacobian[a][e]) / (2.0 * h);
                            assert!(
                                (fd2 - hess[a][e][d]).abs() < 1e-4 * (1.0 + fd2.abs()),
                                "H point {j} [{a}][{e}][{d}]: {fd2} vs {}",
                                hess[a][e][d]
                            );
                        }
                    }
                }
            }
            assert!(forward_kinematics_at(&m, &Q, 3).position[0].is_nan());
        }
    }
}

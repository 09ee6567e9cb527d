//! Does a blob fit the model file it is used with? `cbd eval` and `cbd compensate` read their CSV
//! files through the model file (columns, units, tool points) and evaluate the blob: a blob of
//! three tool points read with a file of one (or the reverse) evaluated every row as the wrong
//! point (66.7 mm "calibrated" error, exit 0). The structure must agree exactly — joints, their
//! kinds, task coordinates, tool points — and the length unit must be the same (the nominal arm's
//! size at the blob's own configurations). The frame may differ: a DH-calibrated blob carries its
//! own base, which is what it evaluates.

use cbd_protocol::{Model, NominalModel};
use cbd_runtime::internals::kinematics::forward_kinematics_at;

/// [`check_blob_fits`], then the import frame: a blob that records the frame its rows were read
/// into (format 9) is used only through a model file whose `spec` reads rows into the same one.
pub fn check_blob_fits_model_file(
    blob: &Model<'_>,
    nominal: &NominalModel,
    spec: &crate::data::column_spec::ColumnSpec,
) -> Result<(), String> {
    check_blob_fits(blob, nominal)?;
    crate::data::import_frame::check_import_frame(blob.provenance.as_ref(), spec)
}

/// Most of the blob's training configurations the size comparison evaluates.
const COMPARED: usize = 64;

/// Why `blob` does not fit the model file's `nominal`, or `Ok`. The caller names both files.
pub fn check_blob_fits(blob: &Model<'_>, nominal: &NominalModel) -> Result<(), String> {
    let (n, m) = (blob.n_joints(), blob.task_dim());
    if n != nominal.n_joints() || m != nominal.task_dim() {
        return Err(format!(
            "the blob's arm has {n} joints and {m}-D positions, the model file's {} joints and {}-D positions",
            nominal.n_joints(),
            nominal.task_dim()
        ));
    }
    let kind = |model: &NominalModel, d: usize| if model.is_revolute(d) { "revolute" } else { "prismatic" };
    if let Some(d) = (0..n).find(|&d| blob.nominal.is_revolute(d) != nominal.is_revolute(d)) {
        return Err(format!("joint {} is {} in the blob and {} in the model file", d + 1, kind(&blob.nominal, d), kind(nominal, d)));
    }
    let (ours, theirs) = (blob.nominal.tool_points(), nominal.tool_points());
    if ours.len() != theirs.len() {
        return Err(format!(
            "the blob was fitted to {} tool point(s) per pose, the model file names {} ([chain] tool points): its rows would be read as the wrong points",
            ours.len().max(1),
            theirs.len().max(1)
        ));
    }
    for (j, (a, b)) in ours.iter().zip(theirs).enumerate() {
        let close = a.iter().zip(b).all(|(x, y)| (x - y).abs() <= 1e-9 * (1.0 + x.abs().max(y.abs())));
        if !close {
            return Err(format!("tool point {} is {a:?} in the blob and {b:?} in the model file", j + 1));
        }
    }
    let (blob_size, file_size) = sizes(blob, nominal);
    let ratio = file_size / blob_size;
    // A DH calibration changes an arm's size by a few per cent; a unit, by 10, 25.4 or 1000.
    if !(0.5..=2.0).contains(&ratio) {
        return Err(format!(
            "the nominal arm is {} times the blob's size at the blob's own configurations (RMS spread {} against {}): another length unit, or another arm",
            crate::error::number(ratio),
            crate::error::number(file_size),
            crate::error::number(blob_size)
        ));
    }
    Ok(())
}

/// The RMS spread about their mean of the blob's nominal tool points and of `nominal`'s at up to
/// [`COMPARED`] of the blob's training configurations (a rigid frame's change leaves it as is).
fn sizes(blob: &Model<'_>, nominal: &NominalModel) -> (f64, f64) {
    let n = blob.n_joints().max(1);
    let points: Vec<f64> = blob.points.iter().collect();
    let configurations: Vec<&[f64]> = points.chunks_exact(n).collect();
    let step = configurations.len().div_ceil(COMPARED).max(1);
    let spread = |model: &NominalModel| {
        let positions: Vec<[f64; 3]> = configurations
            .iter()
            .step_by(step)
            .flat_map(|q| (0..model.tool_point_count()).map(move |j| forward_kinematics_at(model, q, j).position))
            .collect();
        let count = positions.len().max(1) as f64;
        let mean: [f64; 3] = std::array::from_fn(|c| positions.iter().map(|p| p[c]).sum::<f64>() / count);
        (positions.iter().map(|p| (0..3).map(|c| (p[c] - mean[c]).powi(2)).sum::<f64>()).sum::<f64>() / count).sqrt()
    };
    (spread(&blob.nominal), spread(nominal))
}

#[cfg(test)]
mod tests {
    use super::*;
    use cbd_protocol::F64Slice;

    fn blob_of(nominal: NominalModel, points: &[u8], momenta: &[u8], count: u32) -> Model<'static> {
        let points: &'static [u8] = Box::leak(points.to_vec().into_boxed_slice());
        let momenta: &'static [u8] = Box::leak(momenta.to_vec().into_boxed_slice());
        Model {
            n_points: count,
            joint_kernel: cbd_protocol::JointKernel {
                gamma: 1.0,
                axes: heapless::Vec::from_slice(&[cbd_protocol::JointKernelAxis::Periodic { b: 1.0 }; 6]).unwrap(),
            },
            nominal,
            normalisation: cbd_protocol::Normalisation { task_offset: [0.0; 3], task_scale: 500.0 },
            task_kernel: cbd_protocol::TaskKernel { width: 1.0 },
            integrator: cbd_protocol::Integrator { method: cbd_protocol::IntegratorMethod::Euler, steps: 1 },
            momentum_law: cbd_protocol::MomentumLaw::Hamiltonian,
            sigma: 1e-3,
            points: F64Slice::from_le_bytes(points),
            momenta: F64Slice::from_le_bytes(momenta),
            expansion: None,
            noise_sigma: None,
            configuration_kernel: None,
            drift: None,
            provenance: None,
        }
    }

    #[test]
    fn points_units_and_joints_must_agree() {
        let ur5 = || cbd_protocol::ur5::chain();
        let q: Vec<f64> = (0..60).map(|i| (i as f64 * 0.37).sin() * 2.0).collect();
        let (points, momenta) = (cbd_protocol::f64_le_bytes(&q), cbd_protocol::f64_le_bytes(&[0.0; 30]));
        let one = blob_of(NominalModel::DhChain(ur5()), &points, &momenta, 10);
        check_blob_fits(&one, &NominalModel::DhChain(ur5())).unwrap();
        let mut three = ur5();
        three.tool_points = heapless::Vec::from_slice(&[[0.0; 3], [100.0, 0.0, 0.0], [0.0, 100.0, 0.0]]).unwrap();
        let e = check_blob_fits(&one, &NominalModel::DhChain(three.clone())).unwrap_err();
        assert!(e.contains("fitted to 1 tool point(s) per pose, the model file names 3"), "{e}");
        let mut moved = three.clone();
        moved.tool_points[1] = [0.1, 0.0, 0.0];
        let q3: Vec<f64> = q.chunks(6).flat_map(|c| c.repeat(3)).collect();
        let blob3 = blob_of(NominalModel::DhChain(three), &cbd_protocol::f64_le_bytes(&q3), &cbd_protocol::f64_le_bytes(&[0.0; 90]), 30);
        let e = check_blob_fits(&blob3, &NominalModel::DhChain(moved)).unwrap_err();
        assert!(e.contains("tool point 2 is [100.0, 0.0, 0.0] in the blob and [0.1, 0.0, 0.0]"), "{e}");
        // The same arm in metres: 1000 times smaller.
        let mut metres = ur5();
        for j in metres.joints.iter_mut() {
            (j.a, j.d) = (j.a / 1000.0, j.d / 1000.0);
        }
        let e = check_blob_fits(&one, &NominalModel::DhChain(metres)).unwrap_err();
        assert!(e.contains("another length unit"), "{e}");
        // A DH-calibrated blob (its own base far away, lengths 1 % off) fits its file.
        let mut calibrated = ur5();
        calibrated.base.translation = [4000.0, -3000.0, 800.0];
        calibrated.joints[1].a *= 1.01;
        check_blob_fits(&blob_of(NominalModel::DhChain(calibrated), &points, &momenta, 10), &NominalModel::DhChain(ur5())).unwrap();
        let mut prismatic = ur5();
        prismatic.joints[2].kind = cbd_protocol::JointKind::Prismatic;
        let e = check_blob_fits(&one, &NominalModel::DhChain(prismatic)).unwrap_err();
        assert!(e.contains("joint 3 is revolute in the blob and prismatic in the model file"), "{e}");
    }
}

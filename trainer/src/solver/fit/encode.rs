//! The fitted momenta as a blob, checked against the runtime before it is handed out.

use super::{CbdOptions, FitError};
use crate::data::Measurements;
use crate::expansion::ExpansionFit;
use cbd_protocol::{f64_le_bytes, F64Slice, FieldExpansion, Model, NominalModel};

/// The blob for `momenta` (all N·m, internal units) and the expansion, if any, and the largest |runtime − trainer| at the
/// training points relative to the largest |position|.
pub(super) fn encode_checked(
    nominal: &NominalModel,
    data: &Measurements,
    opts: &CbdOptions,
    momenta: &[f64],
    expansion: Option<&ExpansionFit>,
    train_predictions: &[f64],
) -> Result<(Vec<u8>, f64), FitError> {
    let (points, momenta) = (f64_le_bytes(&data.joints), f64_le_bytes(momenta));
    let task_exponents = expansion.map(|e| e.task_exponents()).unwrap_or_default();
    let weights = expansion.map(|e| f64_le_bytes(&e.weights)).unwrap_or_default();
    let model = Model {
        nominal: nominal.clone(),
        normalisation: opts.normalisation.clone(),
        joint_kernel: opts.joint_kernel.clone(),
        task_kernel: opts.task_kernel,
        integrator: opts.integrator,
        momentum_law: opts.solver.law,
        sigma: opts.sigma,
        n_points: data.len() as u32,
        points: F64Slice::from_le_bytes(&points),
        momenta: F64Slice::from_le_bytes(&momenta),
        expansion: expansion.map(|e| FieldExpansion {
            tolerance: e.tolerance,
            task_radius: e.task_radius,
            n_joint_features: e.joint.len() as u32,
            joint_codes: &e.joint.codes,
            n_task_features: e.task.len() as u32,
            task_exponents: &task_exponents,
            weights: F64Slice::from_le_bytes(&weights),
        }),
        noise_sigma: opts.noise_sigma,
        configuration_kernel: opts.configuration_kernel.clone(),
        drift: None,
        provenance: None,
    };
    let blob = cbd_protocol::encode_to_vec(&model).map_err(FitError::Encode)?;
    // Never hand out a blob the runtime does not reproduce.
    let runtime = crate::predict::evaluate_blob(&blob, &data.joints).map_err(|e| FitError::RuntimeMismatch(e.to_string()))?;
    let scale = train_predictions.iter().fold(0.0f64, |s, v| s.max(v.abs())).max(f64::MIN_POSITIVE);
    let max_diff = runtime.iter().zip(train_predictions).fold(0.0f64, |s, (a, b)| s.max((a - b).abs())) / scale;
    if !(max_diff <= 1e-12) {
        return Err(FitError::RuntimeMismatch(format!("largest relative difference at the training points is {max_diff:e} (limit 1e-12)")));
    }
    Ok((blob, max_diff))
}

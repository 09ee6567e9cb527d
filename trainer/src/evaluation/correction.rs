//! A correction fitted on top of a base model — the hook through which kernel ridge, CbD and the
//! hybrids enter a comparison, a commanded-accuracy table or a diagnosis — and its fit on a planar
//! arm's DH form.

use crate::data::Measurements;
use crate::error::Error;
use cbd_protocol::NominalModel;

/// Predicted positions (row-major, `task_dim` per row) at joint rows (row-major).
pub type Predictor = Box<dyn Fn(&[f64]) -> Vec<f64>>;

/// A fitted correction and what was chosen for it.
pub struct FittedCorrection {
    pub predict: Predictor,
    /// One line saying what was chosen (hyperparameters, scheme, warnings).
    pub note: String,
    /// The chosen hyperparameters for a JSON report, when the method has any to report there.
    pub hyperparameters: Option<serde_json::Value>,
    /// The noise σ per coordinate the method's own evidence estimated (data unit), when it has one.
    pub noise_sigma: Option<f64>,
}

impl FittedCorrection {
    /// A correction with its note and nothing for the JSON.
    pub fn new(predict: Predictor, note: String) -> Self {
        FittedCorrection { predict, note, hyperparameters: None, noise_sigma: None }
    }
}

/// Fits a nonparametric correction on top of a nominal model (training rows only).
pub type CorrectionFitter<'a> = &'a dyn Fn(&NominalModel, &Measurements) -> crate::Result<FittedCorrection>;

/// `fit` on `base` for data of `data.task_dim` coordinates. A planar arm's DH form (three) is
/// fitted as the planar chain it is in a moved frame (`nominal::planar::as_planar_in_frame`),
/// the data moved into that frame and the predictions back. (Lifting the data to 3-D instead
/// would hand the correction a noise-free coordinate, which drives its noise estimate to zero.)
pub fn fit_on(fit: CorrectionFitter, base: &NominalModel, data: &Measurements) -> crate::Result<FittedCorrection> {
    use crate::nominal::planar::as_planar_in_frame;
    let (m, full) = (data.task_dim, base.task_dim());
    if m == full {
        return fit(base, data);
    }
    if let (2, Some((chain, frame))) = (m, as_planar_in_frame(base)) {
        let mut moved = Measurements::new(data.n_joints, 2);
        let joints = frame.chain_joints(&data.joints);
        for i in 0..data.len() {
            moved.push(&joints[i * data.n_joints..(i + 1) * data.n_joints], &frame.to_chain(data.position(i)));
        }
        let FittedCorrection { predict, note, hyperparameters, noise_sigma } = fit(&chain, &moved)?;
        let back: Predictor = Box::new(move |joints: &[f64]| {
            predict(&frame.chain_joints(joints)).chunks_exact(2).flat_map(|p| frame.from_chain(p)).collect()
        });
        return Ok(FittedCorrection { predict: back, note, hyperparameters, noise_sigma });
    }
    Err(Error::InvalidInput(format!("a model of {full} task coordinates for data of {m} that is not a planar arm's DH form")))
}

/// `fit` once per tool point of `base` (docs/DESIGN.md §12: kernel ridge is a function of the
/// joints alone, so a pose's points — one configuration, several residuals — get a correction
/// each): point j's on `base` at that point and the rows of point j. Prediction row r is point
/// r mod m_p. A model without tool points is `fit` itself.
pub fn fit_per_tool_point(fit: CorrectionFitter, base: &NominalModel, data: &Measurements) -> crate::Result<FittedCorrection> {
    let points = base.tool_point_count();
    if points == 1 {
        return fit(base, data);
    }
    let mut predictors = Vec::with_capacity(points);
    let mut notes = Vec::with_capacity(points);
    for j in 0..points {
        let model = cbd_runtime::internals::kinematics::tool_point::at_tool_point(base, j)
            .ok_or_else(|| Error::Internal(format!("tool point {j} of {points}")))?;
        let fitted = fit(&model, &data.point(j))?;
        notes.push(format!("point {}: {}", j + 1, fitted.note));
        predictors.push(fitted.predict);
    }
    let (n, m) = (data.n_joints, data.task_dim);
    let predict: Predictor = Box::new(move |joints: &[f64]| {
        let rows = joints.len() / n.max(1);
        let mut out = vec![0.0; rows * m];
        for (j, predict) in predictors.iter().enumerate() {
            let mine: Vec<usize> = (j..rows).step_by(points).collect();
            let q: Vec<f64> = mine.iter().flat_map(|&r| joints[r * n..(r + 1) * n].to_vec()).collect();
            for (k, p) in mine.iter().zip(predict(&q).chunks_exact(m)) {
                out[k * m..(k + 1) * m].copy_from_slice(p);
            }
        }
        out
    });
    Ok(FittedCorrection::new(predict, notes.join("; ")))
}

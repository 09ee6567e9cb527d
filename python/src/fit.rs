//! `cbd.fit`: the library's fit (`cbd_trainer::face::fit`, the one `cbd fit` calls), with the data
//! as arrays made measurements in memory (`face::Dataset::from_rows`) and its settings
//! (`FitSettings`, the command's flags) read from the keywords — so the same data and flags give the
//! same blob bytes.

use crate::commands::{run, typed_args};
use crate::model::Model;
use crate::model_file::{arrays_of, measurements, spec_of, ModelFile, ARRAYS};
use pyo3::prelude::*;
use pyo3::types::PyDict;

/// Fits a calibrated model to measurements: `q` (n, joints) the joint columns and `y` (n, ·) the
/// position columns of the model file's `[measurements]`, in their units — the numbers a CSV for
/// `cbd fit --model …` would hold (`model=None`: the built-in RR arm, q1, q2 in radians, x, y). The
/// model returned takes and gives arrays in the same units (`Model.evaluate(q)` on the training `q`
/// gives positions comparable with `y`).
/// `options` are `cbd fit`'s arguments by the flags' names (`dh_first=True`, `max_rows=500`,
/// `sigma=1e-3`, …; every flag the command has, of its type, with its default). The GIL is released
/// while it runs; progress goes to the "cbd" logger. Raises CbdError with the command's message (an
/// array row is named `(q, y) row r`).
#[pyfunction]
#[pyo3(signature = (model, q, y, **options))]
pub fn fit(
    py: Python<'_>,
    model: Option<PyRef<'_, ModelFile>>,
    q: &Bound<'_, PyAny>,
    y: &Bound<'_, PyAny>,
    options: Option<&Bound<'_, PyDict>>,
) -> PyResult<Model> {
    // The data are the arrays and the blob is returned: neither is a file, nor an option here.
    let settings: cbd_trainer::face::FitSettings = typed_args(py, "fit", options, &["model", "json", "data", "out"])?;
    let (nominal, spec) = spec_of(model.as_deref())?;
    let (q, y) = arrays_of(&spec, q, Some(y))?;
    // The model answers in the arrays' units: the model file's columns (the built-in RR arm's are
    // the blob's own, radians and metres).
    let columns = model.as_ref().map(|m| (m.path.display().to_string(), nominal.clone(), crate::units::Columns { spec: spec.clone() }));
    // The arm as the command would read it, from the file this ModelFile parsed (not parsed again).
    let arm = cbd_trainer::face::ArmModel {
        path: model.as_ref().map(|m| m.path.clone()),
        file: model.as_ref().map(|m| m.file.clone()),
        nominal,
        spec: spec.clone(),
    };
    let fitted = run(py, &[(ARRAYS, ARRAYS)], || cbd_trainer::face::fit(&arm, &measurements(ARRAYS, &spec, &q, y.as_ref())?, &settings))?;
    cbd_trainer::errln!("{}", fitted.summary);
    cbd_trainer::errln!("{}", fitted.noise_floor);
    let report = serde_json::to_string(&fitted.report).map_err(|e| crate::errors::cbd_error(e.to_string()))?;
    py.detach(|| {
        crate::errors::guarded(|| Model::new(fitted.blob, Some(report), columns.as_ref().map(|(f, n, c)| (f.clone(), n, c.clone()))))
    })
    .map_err(|e| e.into_py(&[]))
}

//! `cbd.ModelFile`: a model file (DH table, URDF or planar arm; units; CSV columns), and the one
//! conversion of arrays in its columns' units into the model's, the CSV import's own.

use crate::arrays::{matrix, out2, Rows};
use crate::errors::{cbd_error, Failure};
use cbd_protocol::NominalModel;
use cbd_trainer::face::{ColumnSpec, Dataset, ModelFile as File, OrientationColumns};
use pyo3::prelude::*;
use std::path::PathBuf;

/// What arrays `(q, y)` are called in messages (and where a message names the data's file).
pub const ARRAYS: &str = "(q, y)";

/// A model file, read and checked.
#[pyclass(module = "cbd", frozen)]
pub struct ModelFile {
    pub path: PathBuf,
    pub file: File,
}

#[pymethods]
impl ModelFile {
    /// Reads and checks a model file (TOML: a DH table, a URDF chain or a planar arm; units; the
    /// CSV columns). Raises CbdError naming the file, line, column or field of a fault.
    #[staticmethod]
    fn load(path: PathBuf) -> PyResult<ModelFile> {
        let file = cbd_trainer::face::load_model_file(&path).map_err(|e| cbd_error(e.to_string()))?;
        Ok(ModelFile { path, file })
    }

    /// The file's path as given.
    #[getter]
    fn path(&self) -> String {
        self.path.display().to_string()
    }

    #[getter]
    fn name(&self) -> Option<String> {
        self.file.name.clone()
    }

    /// Joint names: the URDF's, or q1 … qn.
    #[getter]
    fn joint_names(&self) -> Vec<String> {
        self.file.joint_names.clone()
    }

    #[getter]
    fn n_joints(&self) -> usize {
        self.file.nominal.n_joints()
    }

    /// Task-space coordinates per point: 3, or 2 for a planar arm.
    #[getter]
    fn task_dim(&self) -> usize {
        self.file.nominal.task_dim()
    }

    /// The model's length unit (every length of a fitted model is in it).
    #[getter]
    fn length_unit(&self) -> &'static str {
        self.file.length_unit.name()
    }

    /// The columns `q` holds, in order (the file's `[measurements] joints`).
    #[getter]
    fn joint_columns(&self) -> PyResult<Vec<String>> {
        Ok(spec_of(Some(self))?.1.joint_columns)
    }

    /// The columns `y` holds, in order: the positions (per tool point), or a pose's position then
    /// its quaternion or rotation columns.
    #[getter]
    fn position_columns(&self) -> PyResult<Vec<String>> {
        Ok(y_columns(&spec_of(Some(self))?.1))
    }

    /// Converts rows in the file's columns' units (as `fit` takes them: `q` the joint columns, `y`
    /// the position columns) to the model's — radians, the model's length unit, the joint map and a
    /// planar frame applied, a pose read as its tool points — by the CSV import itself. Returns
    /// `(q, y)` with one row per (pose, tool point); with `y=None`, the joints alone.
    #[pyo3(signature = (q, y=None))]
    fn to_model<'py>(
        &self,
        py: Python<'py>,
        q: &Bound<'py, PyAny>,
        y: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<Bound<'py, pyo3::types::PyTuple>> {
        let (_, mut spec) = spec_of(Some(self))?;
        spec.min_rows = 1; // a conversion, not a fit
        if y.is_none() {
            spec.position_columns.clear();
            spec.orientation_columns = None;
            spec.tool_points.clear();
        }
        let (q, y) = arrays_of(&spec, q, y)?;
        let d = measurements(ARRAYS, &spec, &q, y.as_ref()).map_err(|e| Failure(e.to_string()).into_py(&[]))?.imported.measurements;
        let n = d.len();
        let q = out2(py, d.joints, n, d.n_joints);
        let y = out2(py, d.positions, n, d.task_dim);
        pyo3::types::PyTuple::new(py, [q.into_any(), y.into_any()])
    }

    fn __repr__(&self) -> String {
        format!(
            "ModelFile({:?}: {} joints, {})",
            self.path.display().to_string(),
            self.file.nominal.n_joints(),
            self.file.length_unit.name()
        )
    }
}

/// The nominal model and the columns arrays are read as: the model file's `[measurements]` (as
/// `cbd fit` reads a CSV), or, without one, q1 … qn and x, y(, z) per tool point in the file's
/// units; the built-in RR arm (q1, q2 in radians; x, y) for `None`.
pub fn spec_of(model: Option<&ModelFile>) -> PyResult<(NominalModel, ColumnSpec)> {
    let Some(m) = model else {
        let arm = cbd_trainer::face::ArmModel::builtin_rr();
        return Ok((arm.nominal, arm.spec));
    };
    let spec = match m.file.measurements {
        Some(_) => m.file.column_spec().map_err(|e| cbd_error(e.to_string()))?,
        None => {
            let n = m.file.nominal.n_joints();
            let axes = if m.file.nominal.task_dim() == 2 { &["x", "y"][..] } else { &["x", "y", "z"][..] };
            let points = m.file.nominal.tool_point_count();
            let positions =
                (1..=points).flat_map(|j| axes.iter().map(move |a| if points > 1 { format!("{a}{j}") } else { a.to_string() })).collect();
            ColumnSpec {
                tool_points: m.file.nominal.tool_points().to_vec(),
                ..m.file.column_spec_with((1..=n).map(|i| format!("q{i}")).collect(), positions)
            }
        }
    };
    Ok((m.file.nominal.clone(), spec))
}

/// The columns after the joints: positions, then a pose's orientation columns.
pub fn y_columns(spec: &ColumnSpec) -> Vec<String> {
    let mut names = spec.position_columns.clone();
    match &spec.orientation_columns {
        Some(OrientationColumns::Quaternion(v)) | Some(OrientationColumns::Rotation(v)) => names.extend(v.iter().cloned()),
        None => {}
    }
    names
}

/// `q` and `y` checked as matrices of `spec`'s columns (the joints; the positions, then a pose's
/// orientation) with one row of each per measured pose; `y=None`: the joints alone.
pub fn arrays_of(spec: &ColumnSpec, q: &Bound<'_, PyAny>, y: Option<&Bound<'_, PyAny>>) -> PyResult<(Rows, Option<Rows>)> {
    let joints = spec.joint_columns.join(", ");
    // The copy the measurements are built from, per row: joints and positions.
    let q = matrix("q", q, spec.joint_columns.len(), &format!("columns {joints}"), 8 * spec.joint_columns.len())?;
    let y_names = y_columns(spec);
    let y = match y {
        Some(y) => {
            let y = matrix("y", y, y_names.len(), &format!("columns {}", y_names.join(", ")), 8 * y_names.len())?;
            if y.rows != q.rows {
                return Err(cbd_error(format!("q has {} rows and y {}: one row of each per measured pose", q.rows, y.rows)));
            }
            Some(y)
        }
        None => None,
    };
    Ok((q, y))
}

/// Measurements from arrays [`arrays_of`] checked, by the CSV import's own conversion and checks
/// (`face::Dataset::from_rows`): no text between them. `source` names the arrays in messages
/// (`(q, y) row 3: column 'q3_deg': …`).
pub fn measurements(source: &str, spec: &ColumnSpec, q: &Rows, y: Option<&Rows>) -> cbd_trainer::face::Result<Dataset> {
    let y = y.map_or(&[][..], |y| &y.values[..]);
    Dataset::from_rows(source, spec, &q.values, y, q.rows)
}

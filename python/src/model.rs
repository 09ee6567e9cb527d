//! `cbd.Model`: a fitted model's blob, evaluated and compensated by the runtime (the code a
//! controller runs). Arrays in and out are in the units of the model file the model came with (its
//! columns' units, as `cbd fit`'s CSV: `crate::units`); a blob alone is in its own units, joints in
//! radians (prismatic: the model's length unit) in the model's joint order, positions in its length
//! unit — and then the values are the runtime's bit for bit.

use crate::arrays::{matrix, out2, out3};
use crate::errors::{cbd_error, guarded, Failure};
use crate::model_file::{spec_of, ModelFile};
use crate::units::{times, Columns};
use cbd_protocol::NominalModel;
use cbd_runtime::Calibrator;
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyTuple};
use std::path::PathBuf;

/// A calibrated model: the blob `cbd fit` writes, and (after `cbd.fit`) the fit's report.
#[pyclass(module = "cbd", frozen)]
pub struct Model {
    pub blob: Vec<u8>,
    /// The fit's JSON report (what `cbd fit --json` writes), as text.
    pub report: Option<String>,
    n_joints: usize,
    task_dim: usize,
    tool_points: usize,
    /// The model file's columns, when the model came with one: every array in and out is in their units.
    columns: Option<Columns>,
    /// Which joints are revolute (whole turns of them leave the model unchanged).
    periodic: Vec<bool>,
}

impl Model {
    /// A checked model: the blob decodes, the runtime loads it, and it evaluates to finite values
    /// at its own training configurations (`predict::check_calibrator`).
    /// With `model` (the model file's path and its nominal and columns), the blob is checked to fit
    /// it as `cbd eval` checks a blob against `--model`, and arrays are then in its columns' units.
    pub fn new(blob: Vec<u8>, report: Option<String>, model: Option<(String, &NominalModel, Columns)>) -> Result<Model, Failure> {
        let (n_joints, task_dim, tool_points, periodic) = with_calibrator(&blob, |cal| {
            cbd_trainer::face::check_calibrator(cal).map_err(|e| Failure(e.to_string()))?;
            let m = cal.model();
            if let Some((file, nominal, columns)) = &model {
                cbd_trainer::face::check_blob_fits_model_file(m, nominal, &columns.spec)
                    .map_err(|why| Failure(format!("the blob does not fit {file}: {why}")))?;
            }
            let periodic = (0..m.n_joints()).map(|d| m.nominal.is_revolute(d)).collect();
            Ok((m.n_joints(), m.task_dim(), m.nominal.tool_point_count(), periodic))
        })?;
        Ok(Model { blob, report, n_joints, task_dim, tool_points, columns: model.map(|m| m.2), periodic })
    }

    /// `q` as joint rows, each answered by `answer_values` f64 values, in the model's joints.
    fn queries(&self, name: &str, q: &Bound<'_, PyAny>, answer_values: usize) -> PyResult<crate::arrays::Rows> {
        let mut rows = matrix(name, q, self.n_joints, &self.joint_units(), 8 * answer_values)?;
        if let Some(c) = &self.columns {
            let values: Vec<f64> = (0..rows.rows).flat_map(|r| c.joints_in(rows.row(r))).collect();
            rows.values = values;
        }
        Ok(rows)
    }

    /// What a joint array holds, for messages.
    fn joint_units(&self) -> String {
        match &self.columns {
            Some(c) => format!("columns {} in the model file's units", c.spec.joint_columns.join(", ")),
            None => "joints in radians (prismatic: the model's length unit), the model's order".into(),
        }
    }

    /// What a position array holds, for messages.
    fn position_units(&self) -> String {
        match &self.columns {
            Some(c) => format!("positions in {}, as the model file's columns", c.spec.length_unit.name()),
            None => "positions in the model's length unit".into(),
        }
    }

    /// Model positions (rows of `m`) into the arrays' units.
    fn positions_out(&self, p: Vec<f64>, m: usize) -> Vec<f64> {
        match &self.columns {
            Some(c) => p.chunks_exact(m).flat_map(|row| c.position_out(row)).collect(),
            None => p,
        }
    }

    /// Jacobians (rows of `a` × n, the first `positions` rows lengths, the rest dimensionless) into
    /// the arrays' units: ∂y/∂p · J · ∂q/∂c.
    fn jacobians_out(&self, jac: Vec<f64>, a: usize, positions: usize) -> Vec<f64> {
        let Some(c) = &self.columns else { return jac };
        let n = self.n_joints;
        let dq = c.joint_derivative(n);
        let dy = c.position_derivative(positions);
        let mut left = vec![0.0; a * a];
        for i in 0..a {
            for k in 0..a {
                left[i * a + k] = match (i < positions, k < positions) {
                    (true, true) => dy[i * positions + k],
                    (false, false) => f64::from(u8::from(i == k)),
                    _ => 0.0,
                };
            }
        }
        jac.chunks_exact(a * n).flat_map(|j| times(&times(&left, j, a, a, n), &dq, a, n, n)).collect()
    }
}

/// Loads `blob` into a runtime calibrator (storage of its own) for `work`.
fn with_calibrator<T>(blob: &[u8], work: impl FnOnce(&mut Calibrator<'_>) -> Result<T, Failure>) -> Result<T, Failure> {
    let model = cbd_protocol::decode(blob).map_err(|e| Failure(e.to_string()))?;
    let mut storage = vec![0.0; cbd_runtime::storage_len_for(&model)];
    let mut cal = Calibrator::from_model(model, &mut storage).map_err(|e| Failure(e.to_string()))?;
    work(&mut cal)
}

#[pymethods]
impl Model {
    /// A model from blob bytes (checked as `cbd eval` checks a blob file). With `model` (a
    /// ModelFile, checked to fit the blob) arrays in and out are in its columns' units (e.g. degrees
    /// and mm for examples/ur5/ur5.toml); without, in the blob's: radians, the model's length unit.
    #[staticmethod]
    #[pyo3(signature = (data, model=None))]
    fn from_bytes(py: Python<'_>, data: Vec<u8>, model: Option<PyRef<'_, ModelFile>>) -> PyResult<Model> {
        let with = with_file(model.as_deref())?;
        py.detach(|| guarded(|| Model::new(data, None, with.as_ref().map(|(f, n, c)| (f.clone(), n, c.clone())))))
            .map_err(|e| e.into_py(&[]))
    }

    /// Reads a blob file (`cbd fit --out`). With `model` (a ModelFile, checked to fit the blob)
    /// arrays in and out are in its columns' units; without, in the blob's: radians, the model's
    /// length unit.
    #[staticmethod]
    #[pyo3(signature = (path, model=None))]
    fn load(py: Python<'_>, path: PathBuf, model: Option<PyRef<'_, ModelFile>>) -> PyResult<Model> {
        let with = with_file(model.as_deref())?;
        let blob = cbd_trainer::face::read_blob(&path).map_err(|e| cbd_error(e.to_string()))?;
        py.detach(|| guarded(|| Model::new(blob, None, with.as_ref().map(|(f, n, c)| (f.clone(), n, c.clone())))))
            .map_err(|e| cbd_error(format!("{}: {}", path.display(), e.0)))
    }

    /// The units of every array in and out: the model file's columns', or the blob's own.
    #[getter]
    fn units(&self) -> String {
        match &self.columns {
            Some(c) => c.describe(),
            None => "the blob's own: joints in radians (prismatic: the model's length unit) in the model's order, positions in the model's length unit".into(),
        }
    }

    /// The blob's bytes: what `cbd fit` writes, what the runtime and the C library load.
    fn to_bytes<'py>(&self, py: Python<'py>) -> Bound<'py, PyBytes> {
        PyBytes::new(py, &self.blob)
    }

    /// Writes the blob to `path` (atomically: a reader never sees a part-written file).
    fn save(&self, path: PathBuf) -> PyResult<()> {
        cbd_trainer::face::write_atomically(&path, &self.blob).map_err(|e| cbd_error(e.to_string()))
    }

    /// The fit's report (`cbd fit --json`: hyperparameters, evidence, scheme, the fit, warnings) as
    /// a dict; None for a model read from a blob.
    #[getter]
    fn report<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyAny>>> {
        match &self.report {
            Some(text) => Ok(Some(py.import("json")?.call_method1("loads", (text,))?)),
            None => Ok(None),
        }
    }

    #[getter]
    fn n_joints(&self) -> usize {
        self.n_joints
    }

    /// Coordinates of a position: 3, or 2 for a planar arm.
    #[getter]
    fn task_dim(&self) -> usize {
        self.task_dim
    }

    /// Measured points on the tool (1 without `tool.points`).
    #[getter]
    fn tool_point_count(&self) -> usize {
        self.tool_points
    }

    /// The calibrated position of tool point `point` at each row of `q` (n, joints): an (n, task_dim)
    /// array. Units (`Model.units`): with a model file, `q` in its joint columns' units (degrees for
    /// examples/ur5/ur5.toml) and positions in its length unit and frame, as `cbd fit`'s CSV; a blob
    /// alone, radians and the model's length unit, bit for bit what the runtime (and the C library,
    /// the firmware) computes. With `jacobian=True`, `(positions, jacobians)`, the exact Jacobians as
    /// (n, task_dim, joints) in the same units (length per joint column unit).
    #[pyo3(signature = (q, jacobian=false, point=0))]
    fn evaluate<'py>(&self, py: Python<'py>, q: &Bound<'py, PyAny>, jacobian: bool, point: i64) -> PyResult<Bound<'py, PyAny>> {
        let q = self.queries("q", q, self.task_dim * (1 + if jacobian { self.n_joints } else { 0 }))?;
        let Some(point) = usize::try_from(point).ok().filter(|p| *p < self.tool_points) else {
            return Err(cbd_error(format!("point {point}: the model has {} tool point(s) (point is 0-based)", self.tool_points)));
        };
        let (n, m, rows) = (self.n_joints, self.task_dim, q.rows);
        let (positions, jacobians) = py
            .detach(|| {
                guarded(|| {
                    with_calibrator(&self.blob, |cal| {
                        let (mut p, mut jac) = (Vec::with_capacity(rows * m), Vec::with_capacity(if jacobian { rows * m * n } else { 0 }));
                        for r in 0..rows {
                            let e = cal.evaluate_point(q.row(r), point).map_err(|e| Failure(format!("q row {r}: {e}")))?;
                            p.extend(e.position().iter());
                            if jacobian {
                                let j = e.jacobian();
                                jac.extend((0..m).flat_map(|a| (0..n).map(move |d| j[(a, d)])));
                            }
                        }
                        Ok((p, jac))
                    })
                })
            })
            .map_err(|e| e.into_py(&[]))?;
        let positions = out2(py, self.positions_out(positions, m), rows, m).into_any();
        if !jacobian {
            return Ok(positions);
        }
        Ok(PyTuple::new(py, [positions, out3(py, self.jacobians_out(jacobians, m, m), rows, m, n).into_any()])?.into_any())
    }

    /// The calibrated tool frame at each row of `q` (models with 3 or more tool points): `(origins,
    /// rotations)`, (n, 3) and (n, 3, 3) — the least-squares frame of the calibrated points, as the
    /// runtime's `evaluate_pose`. With `jacobian=True` also its (n, 6, joints) Jacobians (origin
    /// rows, then rotation rows). Units as `evaluate`'s: `q` in the model file's joint columns'
    /// units and origins in its length unit (a blob alone: radians, the model's length unit).
    #[pyo3(signature = (q, jacobian=false))]
    fn evaluate_pose<'py>(&self, py: Python<'py>, q: &Bound<'py, PyAny>, jacobian: bool) -> PyResult<Bound<'py, PyTuple>> {
        let q = self.queries("q", q, 12 + if jacobian { 6 * self.n_joints } else { 0 })?;
        let (n, rows) = (self.n_joints, q.rows);
        let (origins, rotations, jacobians) = py
            .detach(|| {
                guarded(|| {
                    with_calibrator(&self.blob, |cal| {
                        let (mut o, mut r, mut jac) = (Vec::new(), Vec::new(), Vec::new());
                        for row in 0..rows {
                            let e = cal.evaluate_pose(q.row(row)).map_err(|e| Failure(format!("q row {row}: {e}")))?;
                            o.extend(e.origin());
                            r.extend(e.rotation().iter().flatten());
                            if jacobian {
                                let j = e.jacobian();
                                jac.extend((0..6).flat_map(|a| (0..n).map(move |d| j[(a, d)])));
                            }
                        }
                        Ok((o, r, jac))
                    })
                })
            })
            .map_err(|e| e.into_py(&[]))?;
        let mut out = vec![out2(py, self.positions_out(origins, 3), rows, 3).into_any(), out3(py, rotations, rows, 3, 3).into_any()];
        if jacobian {
            out.push(out3(py, self.jacobians_out(jacobians, 6, 3), rows, 6, n).into_any());
        }
        PyTuple::new(py, out)
    }

    /// Joint commands that put the calibrated tool at each target (n, task_dim), as `cbd compensate`
    /// computes them. Units as `evaluate`'s: with a model file, targets in its length unit and frame,
    /// seeds and commands in its joint columns' units (commands turned by whole turns into its joint
    /// limits, as `cbd compensate` writes them); a blob alone, the model's length unit and radians.
    /// Commands are computed from `seeds` (n, joints), or without, from the training configuration whose
    /// nominal position is nearest the target; `iterations` Gauss–Newton steps. Returns `(commands,
    /// flags)`: an (n, joints) array and one flag string per row (`ok`, or `not_reached`,
    /// `outside_limits` (a value not finite), `singular`, `extrapolating` joined by `+`; `ok` only when the
    /// command reaches its target at the runtime's tolerance, as `cbd compensate` checks it).
    #[pyo3(signature = (targets, seeds=None, iterations=8))]
    fn compensate<'py>(
        &self,
        py: Python<'py>,
        targets: &Bound<'py, PyAny>,
        seeds: Option<&Bound<'py, PyAny>>,
        iterations: i64,
    ) -> PyResult<Bound<'py, PyTuple>> {
        // The CLI's bound (`cbd compensate --iterations`), checked before any work; a negative or
        // huge int is this error too, never an OverflowError without the argument's name.
        let max = cbd_trainer::face::MAX_ITERATIONS;
        let Some(iterations) = usize::try_from(iterations).ok().filter(|k| (1..=max).contains(k)) else {
            return Err(cbd_error(format!("iterations must be between 1 and {max} (as `cbd compensate --iterations`), got {iterations}")));
        };
        // Per target: its command and the compensation's work rows (a few of the joints' size), a flag.
        let answer = 8 * (4 * self.n_joints + self.task_dim) + 32;
        let mut t = matrix("targets", targets, self.task_dim, &self.position_units(), answer)?;
        if let Some(c) = &self.columns {
            let values: Vec<f64> = (0..t.rows).flat_map(|r| c.position_in(t.row(r))).collect();
            t.values = values;
        }
        let s = seeds.map(|s| self.queries("seeds", s, 0)).transpose()?;
        if let Some(s) = &s {
            if s.rows != t.rows {
                return Err(cbd_error(format!("targets has {} rows and seeds {}: one seed per target", t.rows, s.rows)));
            }
        }
        let (targets, seeds) = (t.to_vecs(), s.map(|s| s.to_vecs()));
        // The commands in model units, flagged as `cbd compensate` flags its rows (a blob alone knows
        // no joint limits, so `outside_limits` is a value that is not finite).
        let rows = py
            .detach(|| {
                guarded(|| {
                    cbd_trainer::face::compensate(&self.blob, &targets, seeds.as_deref(), iterations).map_err(|e| match e {
                        cbd_trainer::face::CompensateError::Row { row, message } => Failure(format!("targets row {row}: {message}")),
                        other => Failure(other.to_string()),
                    })
                })
            })
            .map_err(|e| e.into_py(&[]))?;
        let n = self.n_joints;
        let flags: Vec<String> = rows.iter().map(|r| r.flags.clone()).collect();
        let commands: Vec<f64> = match &self.columns {
            Some(c) => rows.iter().flat_map(|r| c.joints_out(&r.joints, &self.periodic)).collect(),
            None => rows.into_iter().flat_map(|r| r.joints).collect(),
        };
        let commands = out2(py, commands, targets.len(), n);
        PyTuple::new(py, [commands.into_any(), flags.into_pyobject(py)?.into_any()])
    }

    fn __repr__(&self) -> String {
        format!("Model({} joints, {}-D positions, {} bytes)", self.n_joints, self.task_dim, self.blob.len())
    }
}

/// A model file's path, nominal and columns, for a model loaded with it.
fn with_file(model: Option<&ModelFile>) -> PyResult<Option<(String, NominalModel, Columns)>> {
    let Some(m) = model else { return Ok(None) };
    let (nominal, spec) = spec_of(Some(m))?;
    Ok(Some((m.path.display().to_string(), nominal, Columns { spec })))
}

//! `cbd.compare`, `cbd.diagnose`, `cbd.check`, `cbd.simulate`: the library face's operations the commands call
//! after reading their files (`cbd_trainer::face`), in this process, on their settings (keyword
//! arguments by the flags' names); data given as arrays become measurements directly, and results
//! come back as values — no file or text between them.

use crate::arrays::{out2, Rows};
use crate::errors::{cbd_error, guarded, one_at_a_time, Failure};
use crate::model::Model;
use crate::model_file::{arrays_of, measurements, ModelFile};
use cbd_trainer::face::{ColumnSpec, Dataset};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyTuple};
use std::path::PathBuf;

/// Keyword arguments as `cbd <command>`'s typed settings `T` (the face's clap `Args` struct, which is
/// also serde's): `dh_first=True`, `max_rows=500`, `sigma=1e-3`, `effect=[…]` by the flags' own
/// names, each the type the flag reads; `None` is left out (the flag's default) and a path-like
/// object is its path. A name in `reserved` (what the function takes itself or returns) is refused
/// as a keyword. An unknown keyword or a value of the wrong type is a CbdError naming the keyword.
pub fn typed_args<'py, T: serde::de::DeserializeOwned + clap::Args>(
    py: Python<'py>,
    command: &str,
    options: Option<&Bound<'py, PyDict>>,
    reserved: &[&str],
) -> PyResult<T> {
    // The command's flags by name (`--max-rows` → max_rows), for unknown keywords.
    let names: Vec<String> =
        T::augment_args(clap::Command::new("cbd")).get_arguments().filter_map(|a| a.get_long()).map(|l| l.replace('-', "_")).collect();
    let mut keywords: Vec<(String, Bound<'py, PyAny>)> = Vec::new();
    if let Some(options) = options {
        for (key, value) in options.iter() {
            let key: String = key.extract()?;
            if reserved.contains(&key.as_str()) {
                return Err(cbd_error(format!(
                    "{command}(): `{key}` is not an option here (the function takes it as an argument, or returns it)"
                )));
            }
            if !names.contains(&key) {
                let near = names.iter().filter(|n| !reserved.contains(&n.as_str())).min_by_key(|n| distance(n, &key));
                let tip = match near {
                    Some(n) if distance(n, &key) <= 2.max(key.len() / 3) => format!(" (did you mean `{n}`?)"),
                    _ => String::new(),
                };
                return Err(cbd_error(format!("{command}(): unknown keyword `{key}`{tip}")));
            }
            if value.is_none() {
                continue;
            }
            let value = if value.hasattr("__fspath__")? { py.import("os")?.call_method1("fspath", (value,))? } else { value };
            keywords.push((key, value));
        }
    }
    let read = |keywords: &[(String, Bound<'py, PyAny>)]| -> PyResult<Result<T, pythonize::PythonizeError>> {
        let dict = PyDict::new(py);
        for (key, value) in keywords {
            dict.set_item(key, value)?;
        }
        Ok(pythonize::depythonize::<T>(dict.as_any()))
    };
    match read(&keywords)? {
        Ok(args) => Ok(args),
        Err(all) => {
            // The keyword at fault: the first that is refused on its own.
            for keyword in &keywords {
                if let Err(e) = read(std::slice::from_ref(keyword))? {
                    return Err(cbd_error(format!("{command}(): keyword `{}`: {e}", keyword.0)));
                }
            }
            Err(cbd_error(format!("{command}(): {all}")))
        }
    }
}

/// Edit distance of two names (an unknown keyword's nearest flag).
fn distance(a: &str, b: &str) -> usize {
    let b: Vec<char> = b.chars().collect();
    let mut row: Vec<usize> = (0..=b.len()).collect();
    for (i, ca) in a.chars().enumerate() {
        let mut previous = row[0];
        row[0] = i + 1;
        for (j, cb) in b.iter().enumerate() {
            let current = row[j + 1];
            row[j + 1] = (previous + usize::from(ca != *cb)).min(row[j] + 1).min(row[j + 1] + 1);
            previous = current;
        }
    }
    row[b.len()]
}

/// Runs `work` as the binary runs a command (`face::run`: worker pool sized for the memory, outputs
/// staged: written only if it succeeds), GIL released; a failure's messages name `sources`' arrays.
pub fn run<T: Send>(py: Python<'_>, sources: &[(&str, &str)], work: impl FnOnce() -> cbd_trainer::face::Result<T> + Send) -> PyResult<T> {
    py.detach(|| {
        guarded(|| {
            let _one = one_at_a_time();
            cbd_trainer::face::run(work).map_err(Failure::from)
        })
    })
    .map_err(|e| e.into_py(sources))
}

/// A data argument: a CSV path (read by the CSV import, as the command reads it) or `(q, y)`
/// arrays (converted to measurements directly: no text between them).
enum Data {
    File(PathBuf),
    Arrays { label: &'static str, q: Rows, y: Rows },
}

impl Data {
    /// `value` as data with `spec`'s columns; `name` is the argument's, `label` what arrays are
    /// called in messages.
    fn of(spec: &ColumnSpec, value: &Bound<'_, PyAny>, name: &str, label: &'static str) -> PyResult<Data> {
        if let Ok(tuple) = value.cast::<PyTuple>() {
            if tuple.len() != 2 {
                return Err(cbd_error(format!("{name}: give a CSV path or a (q, y) tuple of arrays; got a tuple of {}", tuple.len())));
            }
            let (q, y) = arrays_of(spec, &tuple.get_item(0)?, Some(&tuple.get_item(1)?))?;
            return Ok(Data::Arrays { label, q, y: y.expect("y given") });
        }
        let path: PathBuf = value.extract().map_err(|_| cbd_error(format!("{name}: give a CSV path or a (q, y) tuple of arrays")))?;
        Ok(Data::File(path))
    }

    /// The file, where the data are one (an input the command's outputs must not overwrite).
    fn file(&self) -> Option<&std::path::Path> {
        match self {
            Data::File(path) => Some(path),
            Data::Arrays { .. } => None,
        }
    }

    /// The arrays' label, where messages must name rows rather than lines.
    fn label(&self) -> Option<&'static str> {
        match self {
            Data::File(_) => None,
            Data::Arrays { label, .. } => Some(label),
        }
    }

    fn read(&self, spec: &ColumnSpec) -> cbd_trainer::face::Result<Dataset> {
        match self {
            Data::File(path) => Dataset::read(path, spec),
            Data::Arrays { label, q, y } => measurements(label, spec, q, Some(y)),
        }
    }
}

/// The arrays among `data`, as (what messages call them, what to call them).
fn sources<'a>(data: impl IntoIterator<Item = &'a Data>) -> Vec<(&'static str, &'static str)> {
    data.into_iter().filter_map(Data::label).map(|l| (l, l)).collect()
}

/// A command's JSON value as a Python dict (via the json module: text in memory, no file).
fn json_dict<'py>(py: Python<'py>, value: &serde_json::Value) -> PyResult<Bound<'py, PyAny>> {
    let text = serde_json::to_string(value).map_err(|e| cbd_error(e.to_string()))?;
    py.import("json")?.call_method1("loads", (text,))
}

/// The arm as the command would read it, from the file `model` parsed (not parsed again), or the
/// built-in RR arm.
fn arm_of(model: Option<&ModelFile>) -> PyResult<cbd_trainer::face::ArmModel> {
    match model {
        Some(m) => cbd_trainer::face::ArmModel::from_file(&m.path, m.file.clone()).map_err(|e| cbd_error(e.to_string())),
        None => Ok(cbd_trainer::face::ArmModel::builtin_rr()),
    }
}

/// Every method side by side on the same data, as `cbd compare`: `train` and `test` are CSV paths
/// or `(q, y)` arrays in the model file's columns; `plots` a folder for its figure; `options` are
/// `cbd compare`'s other flags by name. Returns the command's JSON (`--json`) as a dict, keys as
/// the command writes them.
#[pyfunction]
#[pyo3(signature = (model, train, test, plots=None, **options))]
pub fn compare<'py>(
    py: Python<'py>,
    model: PyRef<'py, ModelFile>,
    train: &Bound<'py, PyAny>,
    test: &Bound<'py, PyAny>,
    plots: Option<PathBuf>,
    options: Option<&Bound<'py, PyDict>>,
) -> PyResult<Bound<'py, PyAny>> {
    let arm = arm_of(Some(&model))?;
    let train = Data::of(&arm.spec, train, "train", "train (q, y)")?;
    let test = Data::of(&arm.spec, test, "test", "test (q, y)")?;
    let settings: cbd_trainer::face::CompareSettings = typed_args(py, "compare", options, &["json"])?;
    let json = run(py, &sources([&train, &test]), || {
        // The command's checks of its paths before any work (its outputs here: the figures).
        let inputs = [("--model", arm.path.as_deref()), ("--train", train.file()), ("--test", test.file())];
        cbd_trainer::face::check_paths(&inputs, &[])?;
        if let Some(dir) = &plots {
            cbd_trainer::face::check_output_dir("--plots", dir)?;
        }
        settings.check(&arm)?;
        let (train, test) = (train.read(&arm.spec)?, test.read(&arm.spec)?);
        let c = cbd_trainer::face::compare(&arm, &train, &test, &settings)?;
        // The lines the command prints, as messages.
        cbd_trainer::errln!("{}", c.table());
        for note in c.notes() {
            cbd_trainer::errln!("{note}");
        }
        if let Some(dir) = &plots {
            let files = c.write_figures(dir)?;
            cbd_trainer::errln!("figures written to {} ({files} files)", dir.display());
        }
        if let Some(table) = c.commanded_table() {
            cbd_trainer::errln!("{table}");
        }
        Ok(c.to_json())
    })?;
    json_dict(py, &json)
}

/// Traces the residual to physical effects, as `cbd diagnose`: `data` (and `test`) CSV paths or
/// `(q, y)` arrays; `plots` a folder for its figures, `write_model` a path for the model file with
/// the corrections found; `options` are its other flags by name (`harmonics=3`, `no_cbd=True`).
/// Returns its JSON as a dict.
#[pyfunction]
#[pyo3(signature = (model, data, test=None, plots=None, write_model=None, **options))]
#[allow(clippy::too_many_arguments)]
pub fn diagnose<'py>(
    py: Python<'py>,
    model: Option<PyRef<'py, ModelFile>>,
    data: &Bound<'py, PyAny>,
    test: Option<&Bound<'py, PyAny>>,
    plots: Option<PathBuf>,
    write_model: Option<PathBuf>,
    options: Option<&Bound<'py, PyDict>>,
) -> PyResult<Bound<'py, PyAny>> {
    let arm = arm_of(model.as_deref())?;
    let data = Data::of(&arm.spec, data, "data", "data (q, y)")?;
    let test = test.map(|t| Data::of(&arm.spec, t, "test", "test (q, y)")).transpose()?;
    let settings: cbd_trainer::face::DiagnoseSettings = typed_args(py, "diagnose", options, &["json"])?;
    let with_file = model.is_some();
    let json = run(py, &sources(std::iter::once(&data).chain(&test)), || {
        settings.validate()?;
        if write_model.is_some() && !with_file {
            return Err(cbd_trainer::face::Error::InvalidInput(
                "--write-model needs --model (the file the corrections are written into)".into(),
            ));
        }
        // The command's checks of its paths before any work (its outputs here: the model file
        // written and the figures).
        let inputs = [("--model", arm.path.as_deref()), ("--data", data.file()), ("--test", test.as_ref().and_then(Data::file))];
        cbd_trainer::face::check_paths(&inputs, &[("--write-model", write_model.as_deref())])?;
        if let Some(dir) = &plots {
            cbd_trainer::face::check_output_dir("--plots", dir)?;
        }
        let measured = data.read(&arm.spec)?;
        let test = test.as_ref().map(|t| t.read(&arm.spec)).transpose()?;
        let d = cbd_trainer::face::diagnose(&arm, &measured, test.as_ref(), &settings)?;
        // The lines the command prints, as messages.
        cbd_trainer::errln!("{}", d.text());
        if let Some(dir) = &plots {
            let files = d.write_figures(dir)?;
            cbd_trainer::errln!("figures written to {} ({files} files)", dir.display());
        }
        if let Some(path) = &write_model {
            if let Some(text) = d.model_file(&arm, path)? {
                cbd_trainer::face::write_atomically(path, text.as_bytes())?;
                cbd_trainer::errln!("model with the found effects written to {}", path.display());
            }
        }
        Ok(d.to_json())
    })?;
    json_dict(py, &json)
}

/// Does a calibration still hold, as `cbd check`: `blob` a Model (from `fit` or `Model.load`) or a
/// blob file's path, `data` fresh poses (a CSV path or `(q, y)` arrays in the model file's columns,
/// in measurement order), `alpha` the test's level, `register` to fit the fresh rows' rigid frame
/// first (also when the model file's base is `register = true`). Returns the command's JSON
/// (`--json`) as a dict: `verdict` ("holds" or "changed"), `p_value`, `statistic`, `dof`, the error
/// against the floor, and when it changed the named change. (`--update` and `--log`, which write
/// files, are the command's.)
#[pyfunction]
#[pyo3(signature = (model, blob, data, alpha=0.01, register=false))]
pub fn check<'py>(
    py: Python<'py>,
    model: Option<PyRef<'py, ModelFile>>,
    blob: &Bound<'py, PyAny>,
    data: &Bound<'py, PyAny>,
    alpha: f64,
    register: bool,
) -> PyResult<Bound<'py, PyAny>> {
    let arm = arm_of(model.as_deref())?;
    let settings = cbd_trainer::face::CheckSettings { alpha, register, update: false };
    settings.validate().map_err(|e| cbd_error(e.to_string()))?;
    // A Model's bytes, or a path read inside (as the command reads --blob).
    let (bytes, source) = match blob.extract::<PyRef<'py, Model>>() {
        Ok(m) => (Some(m.blob.clone()), PathBuf::from("(the Model given)")),
        Err(_) => {
            let path = if blob.hasattr("__fspath__")? { py.import("os")?.call_method1("fspath", (blob,))? } else { blob.clone() };
            let path: PathBuf = path.extract().map_err(|_| cbd_error("blob: give a cbd.Model or a blob file's path"))?;
            (None, path)
        }
    };
    let data = Data::of(&arm.spec, data, "data", "data (q, y)")?;
    let json = run(py, &sources([&data]), || {
        let from_file = bytes.is_none().then_some(source.as_path());
        let inputs = [("--model", arm.path.as_deref()), ("--blob", from_file), ("--data", data.file())];
        cbd_trainer::face::check_paths(&inputs, &[])?;
        let bytes = match bytes {
            Some(b) => b,
            None => cbd_trainer::face::read_blob(&source)?,
        };
        let decoded = cbd_trainer::face::decode_blob(&bytes, &source, arm.path.as_deref(), &arm.nominal, &arm.spec)?;
        let fresh = data.read(&arm.spec)?;
        let blob = cbd_trainer::face::DecodedBlob { model: decoded, source: &source };
        let checked = cbd_trainer::face::check(&arm, blob, &bytes, &fresh, &settings)?;
        Ok(checked.to_json(None))
    })?;
    json_dict(py, &json)
}

/// Simulated measurements, as `cbd simulate` (its flags by name: `robot="six"`, `sampling="uniform"`,
/// `count=300`, `seed=1`, `noise=0.02`, `effect=[…]`, …). Returns `(q, y)`: the CSV's joint columns
/// and its other columns (positions, per tool point; with `pose=True` then the quaternion), in the
/// CSV's units — what `fit` takes with the matching model file (rr: none; six:
/// examples/ur5/simulated-six.toml). `poses`: a CSV of poses to measure at instead of sampling
/// (`cbd simulate --poses`).
#[pyfunction]
#[pyo3(signature = (poses=None, **options))]
pub fn simulate<'py>(py: Python<'py>, poses: Option<PathBuf>, options: Option<&Bound<'py, PyDict>>) -> PyResult<Bound<'py, PyTuple>> {
    // The rows come back as arrays: `out` is not written.
    let settings: cbd_trainer::face::SimulateSettings = typed_args(py, "simulate", options, &["out"])?;
    let simulated = run(py, &[], || {
        // The flags are checked before the poses are read: a wrong flag is named first.
        settings.check(poses.is_some())?;
        let poses = match &poses {
            Some(path) => Some(Dataset::read(path, &cbd_trainer::face::poses_spec(&settings.robot))?.imported.measurements.joints),
            None => None,
        };
        cbd_trainer::face::simulate(&settings, poses)
    })?;
    // Joint columns: q1, q2 (rr) or q1_deg … (six); the quaternion's are qw, qx, ….
    let header = &simulated.header;
    let n = header.iter().take_while(|h| h.strip_prefix('q').is_some_and(|r| r.starts_with(|c: char| c.is_ascii_digit()))).count();
    let (rows, width) = (simulated.rows(), header.len());
    let (mut q, mut y) = (Vec::with_capacity(rows * n), Vec::with_capacity(rows * (width - n)));
    for row in simulated.values.chunks_exact(width.max(1)) {
        q.extend_from_slice(&row[..n]);
        y.extend_from_slice(&row[n..]);
    }
    PyTuple::new(py, [out2(py, q, rows, n).into_any(), out2(py, y, rows, width - n).into_any()])
}

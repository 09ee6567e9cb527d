//! `cbd.compare`, `cbd.diagnose`, `cbd.simulate`: the commands themselves, run in this process on
//! their own flags (keyword arguments), data given as arrays written to CSV files they read and
//! their JSON or CSV output read back — no second pipeline.

use crate::arrays::out2;
use crate::errors::{cbd_error, guarded, one_at_a_time, Failure};
use crate::model_file::{arrays_csv, spec_of, ModelFile};
use clap::Parser;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyTuple};
use std::path::{Path, PathBuf};

/// Keyword arguments as `cbd <command>` flags: `dh_first=True` → `--dh-first`, `max_rows=500` →
/// `--max-rows=500`, a list or tuple → the flag once per item, `False`/`None` → left out. A name
/// in `reserved` (the data, the outputs) is refused: the function takes those itself.
pub fn flags_from_options(command: &str, options: Option<&Bound<'_, PyDict>>, reserved: &[&str]) -> PyResult<Vec<String>> {
    let mut flags = Vec::new();
    let Some(options) = options else { return Ok(flags) };
    for (key, value) in options.iter() {
        let key: String = key.extract()?;
        if reserved.contains(&key.as_str()) {
            return Err(cbd_error(format!(
                "{command}(): `{key}` is not an option here (the function takes it as an argument, or returns it)"
            )));
        }
        let flag = format!("--{}", key.replace('_', "-"));
        let items: Vec<Bound<'_, PyAny>> = if value.is_instance_of::<pyo3::types::PyList>() || value.is_instance_of::<PyTuple>() {
            value.try_iter()?.collect::<PyResult<_>>()?
        } else {
            vec![value]
        };
        for item in items {
            if item.is_none() {
                continue;
            }
            if let Ok(b) = item.cast::<pyo3::types::PyBool>() {
                if b.is_true() {
                    flags.push(flag.clone());
                }
                continue;
            }
            // str() of a float is its shortest round-trip form: the command reads the same number.
            flags.push(format!("{flag}={}", item.str()?));
        }
    }
    Ok(flags)
}

/// `cbd <args>` parsed by the command line's own parser; its error (an unknown flag, a bad value) as
/// a CbdError, without the usage lines.
pub fn command_args(args: &[String]) -> PyResult<cbd_trainer::cli::Command> {
    let argv = std::iter::once("cbd".to_string()).chain(args.iter().cloned());
    match cbd_trainer::cli::Cli::try_parse_from(argv) {
        Ok(cli) => Ok(cli.command),
        Err(e) => {
            let text = e.render().to_string();
            let first = text.split("\n\nUsage:").next().unwrap_or(&text).trim();
            Err(cbd_error(first.strip_prefix("error: ").unwrap_or(first).to_string()))
        }
    }
}

/// Runs `cbd <args>` as the binary would (worker pool sized for the memory), GIL released.
fn run(py: Python<'_>, args: Vec<String>, sources: &[(&str, &str)]) -> PyResult<()> {
    let command = command_args(&args)?;
    py.detach(|| {
        guarded(|| {
            let _one = one_at_a_time();
            cbd_trainer::cli::run(cbd_trainer::cli::Cli { command }).map_err(Failure::from)
        })
    })
    .map_err(|e| e.into_py(sources))
}

/// A data argument: a CSV path, or `(q, y)` arrays written to `dir/name.csv` (and then named
/// `label` in messages: pushed onto `named`).
fn data_path(
    model: Option<&ModelFile>,
    value: &Bound<'_, PyAny>,
    dir: &Path,
    name: &str,
    label: &'static str,
    named: &mut Vec<(PathBuf, &'static str)>,
) -> PyResult<PathBuf> {
    if let Ok(tuple) = value.cast::<PyTuple>() {
        if tuple.len() != 2 {
            return Err(cbd_error(format!("{name}: give a CSV path or a (q, y) tuple of arrays; got a tuple of {}", tuple.len())));
        }
        let (_, spec) = spec_of(model)?;
        let text = arrays_csv(&spec, &tuple.get_item(0)?, Some(&tuple.get_item(1)?))?;
        let path = dir.join(format!("{name}.csv"));
        std::fs::write(&path, text).map_err(|e| cbd_error(format!("{}: {e}", path.display())))?;
        named.push((path.clone(), label));
        return Ok(path);
    }
    let path: PathBuf = value.extract().map_err(|_| cbd_error(format!("{name}: give a CSV path or a (q, y) tuple of arrays")))?;
    Ok(path)
}

fn scratch() -> PyResult<tempfile::TempDir> {
    tempfile::Builder::new().prefix("cbd-python-").tempdir().map_err(|e| cbd_error(format!("a temporary directory: {e}")))
}

/// The JSON a command wrote, as a dict.
fn json_dict<'py>(py: Python<'py>, path: &Path) -> PyResult<Bound<'py, PyAny>> {
    let text = std::fs::read_to_string(path).map_err(|e| cbd_error(format!("{}: {e}", path.display())))?;
    py.import("json")?.call_method1("loads", (text,))
}

/// The stand-ins of array data in messages: the temporary file's path → "train (q, y)".
fn sources(paths: &[(PathBuf, &'static str)]) -> Vec<(String, &'static str)> {
    paths.iter().map(|(p, name)| (p.display().to_string(), *name)).collect()
}

/// Every method side by side on the same data, as `cbd compare`: `train` and `test` are CSV paths
/// or `(q, y)` arrays in the model file's columns; `options` are `cbd compare`'s flags by name.
/// Returns the command's JSON (`--json`) as a dict, keys as the command writes them.
#[pyfunction]
#[pyo3(signature = (model, train, test, **options))]
pub fn compare<'py>(
    py: Python<'py>,
    model: PyRef<'py, ModelFile>,
    train: &Bound<'py, PyAny>,
    test: &Bound<'py, PyAny>,
    options: Option<&Bound<'py, PyDict>>,
) -> PyResult<Bound<'py, PyAny>> {
    let dir = scratch()?;
    let mut named = Vec::new();
    let train = data_path(Some(&model), train, dir.path(), "train", "train (q, y)", &mut named)?;
    let test = data_path(Some(&model), test, dir.path(), "test", "test (q, y)", &mut named)?;
    let json = dir.path().join("compare.json");
    let mut args: Vec<String> = ["compare", "--model"].map(String::from).into();
    args.push(model.path.display().to_string());
    for (flag, path) in [("--train", &train), ("--test", &test), ("--json", &json)] {
        args.extend([flag.to_string(), path.display().to_string()]);
    }
    args.extend(flags_from_options("compare", options, &["model", "train", "test", "json"])?);
    let named = sources(&named);
    run(py, args, &named.iter().map(|(p, n)| (p.as_str(), *n)).collect::<Vec<_>>())?;
    json_dict(py, &json)
}

/// Traces the residual to physical effects, as `cbd diagnose`: `data` (and `test`) CSV paths or
/// `(q, y)` arrays; `options` are its flags by name (`harmonics=3`, `no_cbd=True`, `write_model=…`).
/// Returns its JSON as a dict.
#[pyfunction]
#[pyo3(signature = (model, data, test=None, **options))]
pub fn diagnose<'py>(
    py: Python<'py>,
    model: Option<PyRef<'py, ModelFile>>,
    data: &Bound<'py, PyAny>,
    test: Option<&Bound<'py, PyAny>>,
    options: Option<&Bound<'py, PyDict>>,
) -> PyResult<Bound<'py, PyAny>> {
    let dir = scratch()?;
    let mut named = Vec::new();
    let data = data_path(model.as_deref(), data, dir.path(), "data", "data (q, y)", &mut named)?;
    let json = dir.path().join("diagnose.json");
    let mut args: Vec<String> =
        vec!["diagnose".into(), "--data".into(), data.display().to_string(), "--json".into(), json.display().to_string()];
    if let Some(m) = &model {
        args.extend(["--model".into(), m.path.display().to_string()]);
    }
    if let Some(test) = test {
        let test = data_path(model.as_deref(), test, dir.path(), "test", "test (q, y)", &mut named)?;
        args.extend(["--test".into(), test.display().to_string()]);
    }
    args.extend(flags_from_options("diagnose", options, &["model", "data", "test", "json"])?);
    let named = sources(&named);
    run(py, args, &named.iter().map(|(p, n)| (p.as_str(), *n)).collect::<Vec<_>>())?;
    json_dict(py, &json)
}

/// Simulated measurements, as `cbd simulate` (its flags by name: `robot="six"`, `sampling="uniform"`,
/// `count=300`, `seed=1`, `noise=0.02`, `effect=[…]`, …). Returns `(q, y)`: the CSV's joint columns
/// and its other columns (positions, per tool point; with `pose=True` then the quaternion), in the
/// CSV's units — what `fit` takes with the matching model file (rr: none; six:
/// examples/ur5/simulated-six.toml).
#[pyfunction]
#[pyo3(signature = (**options))]
pub fn simulate<'py>(py: Python<'py>, options: Option<&Bound<'py, PyDict>>) -> PyResult<Bound<'py, PyTuple>> {
    let dir = scratch()?;
    let out = dir.path().join("simulated.csv");
    let mut args: Vec<String> = vec!["simulate".into(), "--out".into(), out.display().to_string()];
    args.extend(flags_from_options("simulate", options, &["out"])?);
    run(py, args, &[])?;
    let text = std::fs::read_to_string(&out).map_err(|e| cbd_error(format!("{}: {e}", out.display())))?;
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap_or("").split(',').collect();
    // Joint columns: q1, q2 (rr) or q1_deg … (six); the quaternion's are qw, qx, ….
    let n = header.iter().take_while(|h| h.strip_prefix('q').is_some_and(|r| r.starts_with(|c: char| c.is_ascii_digit()))).count();
    let (mut q, mut y, mut rows) = (Vec::new(), Vec::new(), 0);
    for (k, line) in lines.enumerate() {
        let values: Vec<f64> = line
            .split(',')
            .map(|v| v.parse::<f64>())
            .collect::<Result<_, _>>()
            .map_err(|e| Failure(format!("{}:{}: {e}", out.display(), k + 2)).into_py(&[]))?;
        q.extend_from_slice(&values[..n]);
        y.extend_from_slice(&values[n..]);
        rows += 1;
    }
    let m = header.len() - n;
    PyTuple::new(py, [out2(py, q, rows, n).into_any(), out2(py, y, rows, m).into_any()])
}

//! `cbd.CbdError`: every failure, with the message the `cbd` command prints for it.

use pyo3::prelude::*;

pyo3::create_exception!(
    cbd,
    CbdError,
    pyo3::exceptions::PyValueError,
    "A cbd failure: bad input (file, line, column or field named), a model that cannot be used, or a fit that failed. The message is the one the `cbd` command prints."
);

/// A `CbdError` with `message`.
pub fn cbd_error(message: impl Into<String>) -> PyErr {
    CbdError::new_err(message.into())
}

/// A `cbd.CbdMemoryError` with `message`: a `CbdError` that is also a `MemoryError`, raised where
/// an array is refused before it is copied because this process's memory could not hold it (the
/// class is the package's, `python/cbd/__init__.py`; a `CbdError` if it cannot be found).
pub fn memory_error(py: Python<'_>, message: String) -> PyErr {
    let class = py.import("cbd").and_then(|m| m.getattr("CbdMemoryError")).ok().and_then(|c| c.cast_into::<pyo3::types::PyType>().ok());
    match class {
        Some(class) => PyErr::from_type(class, message),
        None => cbd_error(message),
    }
}

/// A failure carried out of a detached call (the GIL released): only its message.
pub struct Failure(pub String);

impl From<cbd_trainer::face::Error> for Failure {
    fn from(e: cbd_trainer::face::Error) -> Failure {
        Failure(e.to_string())
    }
}

impl From<String> for Failure {
    fn from(message: String) -> Failure {
        Failure(message)
    }
}

impl Failure {
    /// As a `CbdError`, each input's stand-in path (`sources`: what the message says, what to call
    /// it) renamed, and its CSV line numbers read as 0-based array rows (line = row + 2: the header
    /// is line 1).
    pub fn into_py(self, sources: &[(&str, &str)]) -> PyErr {
        let mut message = self.0;
        for (path, name) in sources {
            message = rows_for_lines(&message, path, name);
        }
        cbd_error(message)
    }
}

/// `text` with every `path:LINE` as `name row LINE−2` and every other `path` as `name`.
fn rows_for_lines(text: &str, path: &str, name: &str) -> String {
    let mut out = String::new();
    let mut rest = text;
    while let Some(at) = rest.find(path) {
        out.push_str(&rest[..at]);
        rest = &rest[at + path.len()..];
        let digits: String = rest.strip_prefix(':').map(|r| r.chars().take_while(char::is_ascii_digit).collect()).unwrap_or_default();
        match digits.parse::<u64>() {
            Ok(line) if line >= 2 => {
                out.push_str(&format!("{name} row {}", line - 2));
                rest = &rest[1 + digits.len()..];
            }
            _ => out.push_str(name),
        }
    }
    out.push_str(rest);
    out
}

/// Runs `work`, a panic (a bug) becoming a failure rather than unwinding into Python.
pub fn guarded<T>(work: impl FnOnce() -> Result<T, Failure>) -> Result<T, Failure> {
    match std::panic::catch_unwind(std::panic::AssertUnwindSafe(work)) {
        Ok(result) => result,
        Err(panic) => {
            let what = panic.downcast_ref::<String>().cloned().or_else(|| panic.downcast_ref::<&str>().map(|s| s.to_string()));
            Err(Failure(format!("internal error (a bug to report): {}", what.unwrap_or_else(|| "a panic".into()))))
        }
    }
}

/// One command or fit at a time in this process: the trainer's worker pool and its record of
/// the files a run reads are the process's.
pub fn one_at_a_time() -> std::sync::MutexGuard<'static, ()> {
    static RUNS: std::sync::Mutex<()> = std::sync::Mutex::new(());
    // `face::run` starts the record of the files a run reads afresh.
    RUNS.lock().unwrap_or_else(|e| e.into_inner())
}

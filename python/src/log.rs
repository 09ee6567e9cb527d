//! The trainer's message lines (what `cbd` prints on stderr and stdout) as records of Python's
//! `logging` logger "cbd": warnings at WARNING, the rest at INFO. Never the interpreter's stdout.

use pyo3::prelude::*;

/// Installs the trainer's message sink for this process.
pub fn route_messages_to_logging() {
    cbd_trainer::face::set_message_sink(Some(Box::new(|_stream, line| {
        // Fits run with the GIL released, on worker threads: each line takes it for its record.
        Python::attach(|py| {
            if let Err(e) = emit(py, line) {
                e.print(py);
            }
        });
    })));
}

fn emit(py: Python<'_>, line: &str) -> PyResult<()> {
    let logger = py.import("logging")?.call_method1("getLogger", ("cbd",))?;
    let level = if line.starts_with("warning") { "warning" } else { "info" };
    logger.call_method1(level, (line,))?;
    Ok(())
}

//! The `cbd` Python package's native module (`cbd._cbd`): numpy in, numpy out, every pipeline the
//! `cbd` command's own (a fit through the library's face, `face::fit`, compare/diagnose/check/simulate as the
//! commands themselves), evaluation and compensation the runtime's. Messages go to Python's
//! `logging` (logger "cbd"), never to stdout; errors raise `cbd.CbdError` with the command's message.

mod arrays;
mod commands;
mod errors;
mod fit;
mod log;
mod model;
mod model_file;
mod units;

use pyo3::prelude::*;

#[pymodule]
mod _cbd {
    #[pymodule_export]
    use super::commands::{check, compare, diagnose, simulate};
    #[pymodule_export]
    use super::errors::CbdError;
    #[pymodule_export]
    use super::fit::fit;
    #[pymodule_export]
    use super::model::Model;
    #[pymodule_export]
    use super::model_file::ModelFile;
    use pyo3::prelude::*;

    #[pymodule_init]
    fn init(m: &Bound<'_, PyModule>) -> PyResult<()> {
        super::log::route_messages_to_logging();
        m.add("__version__", env!("CARGO_PKG_VERSION"))
    }
}

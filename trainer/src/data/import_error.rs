//! Why a model file or a measurement file could not be read.

use std::fmt;
use std::path::PathBuf;

/// Any failure to read a model file or a measurement file. Display gives the file, and for CSV
/// data the line and column.
#[derive(Debug, Clone, PartialEq)]
pub enum ImportError {
    /// The file could not be read.
    Io { file: PathBuf, message: String },
    /// The model file is not valid TOML for the schema (unknown field, wrong type, …); the
    /// message comes from the TOML parser and names the field and position.
    Toml { file: PathBuf, message: String },
    /// The model file parses but describes no valid model.
    Model { file: PathBuf, message: String },
    /// One field or section of a model file is not valid: `field` names it (`[chain.base]`).
    Field { file: PathBuf, field: String, message: String },
    /// A URDF file could not be read or converted.
    Urdf { file: PathBuf, message: String },
    /// A problem in a CSV file. `line` is 1-based (the header is line 1); `column` is the
    /// column's name where one applies.
    Csv { file: PathBuf, line: Option<u64>, column: Option<String>, message: String },
    /// A problem in rows of numbers given in memory (arrays): `source` names them (`(q, y)`),
    /// `row` is 0-based, `column` the column's name where one applies.
    Rows { source: String, row: Option<u64>, column: Option<String>, message: String },
}

impl fmt::Display for ImportError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ImportError::Io { file, message } => write!(f, "{}: {message}", file.display()),
            ImportError::Toml { file, message } => write!(f, "{}: {}", file.display(), message.trim_end()),
            ImportError::Model { file, message } => write!(f, "{}: {message}", file.display()),
            ImportError::Field { file, field, message } => write!(f, "{}: {field}: {message}", file.display()),
            ImportError::Urdf { file, message } => write!(f, "{}: URDF: {message}", file.display()),
            ImportError::Csv { file, line, column, message } => {
                write!(f, "{}", file.display())?;
                if let Some(l) = line {
                    write!(f, ":{l}")?;
                }
                if let Some(c) = column {
                    write!(f, ": column '{c}'")?;
                }
                write!(f, ": {message}")
            }
            ImportError::Rows { source, row, column, message } => {
                write!(f, "{source}")?;
                if let Some(r) = row {
                    write!(f, " row {r}")?;
                }
                if let Some(c) = column {
                    write!(f, ": column '{c}'")?;
                }
                write!(f, ": {message}")
            }
        }
    }
}

impl std::error::Error for ImportError {}

impl From<ImportError> for crate::Error {
    fn from(e: ImportError) -> crate::Error {
        crate::Error::stage("import", e)
    }
}

//! The trainer's one error type. Each variant carries what a user needs to find the problem
//! (the file, line, column or field; the joint; the configuration row) and its `Display` is the
//! message the `cbd` command prints. The stage errors (`FitError`, `EvidenceError`, …) stay where
//! their stage is and enter here unchanged, so their messages do not change either.

use std::path::PathBuf;

pub use crate::data::import_error::ImportError;

/// Any failure of the trainer's library (the CLI turns it into its `error: …` line).
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A file or directory could not be read, created or written.
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// Standard output (`--out -`) could not be written.
    #[error("standard output: {0}")]
    Stdout(#[source] std::io::Error),
    /// A path that may not or cannot be written or read as asked: a symbolic link or a directory
    /// where an output file goes, a missing or read-only directory, a file over the size cap.
    #[error("{}: {reason}", path.display())]
    Path { path: PathBuf, reason: String },
    /// A JSON file (a fit's `--json` output) that does not parse.
    #[error("{}: line {line}, column {column}: {error}", path.display())]
    Json { path: PathBuf, line: usize, column: usize, error: serde_json::Error },
    /// A model file or measurement file: names the file and, for CSV data, the line and column.
    #[error(transparent)]
    Import(#[from] ImportError),
    /// A URDF chain that cannot be converted to DH (no file: the model file reader adds it).
    #[error("{0}")]
    Urdf(String),
    /// The nominal model is unusable at a measured configuration: names the file and line.
    #[error("{}:{line}: {message}", file.display())]
    NominalAtRow { file: PathBuf, line: u64, message: String },
    /// Inputs or options that do not fit together (joint counts, a name not known, an empty list).
    #[error("{0}")]
    InvalidInput(String),
    /// A factorisation failed (non-finite data).
    #[error("{0}")]
    Numerical(String),
    /// A figure could not be drawn.
    #[error("{0}")]
    Plot(String),
    /// A blob could not be decoded.
    #[error(transparent)]
    Decode(#[from] cbd_protocol::DecodeError),
    /// The runtime refused a blob (the runtime's error is `no_std`: not a `std` error source).
    #[error("{0}")]
    Runtime(cbd_runtime::Error),
    /// The runtime could not evaluate configuration `row` (0-based) of a query.
    #[error("configuration {row}: {error}")]
    Evaluate { row: usize, error: cbd_runtime::Error },
    #[error(transparent)]
    Fit(#[from] crate::solver::FitError),
    #[error(transparent)]
    Evidence(#[from] crate::kernels::evidence::EvidenceError),
    #[error(transparent)]
    Hyperparameters(#[from] crate::kernels::hyperparameters::HyperparameterError),
    #[error(transparent)]
    KernelRidge(#[from] crate::baselines::krr::KrrError),
    #[error(transparent)]
    LeastSquares(#[from] crate::solver::least_squares::LeastSquaresError),
    #[error(transparent)]
    DhCalibration(#[from] crate::parametric::DhCalibrationError),
    /// A `--effect` specification of `cbd simulate` that does not parse.
    #[error(transparent)]
    EffectSpec(#[from] crate::simulate::effects::EffectSpecError),
    #[error(transparent)]
    Diagnose(#[from] crate::diagnose::error::DiagnoseError),
    /// Any of the above, with what was being done: `--commanded: unknown simulated robot`.
    #[error("{context}: {source}")]
    Context {
        context: String,
        #[source]
        source: Box<Error>,
    },
}

impl Error {
    /// An I/O failure at `path`.
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Error {
        Error::Io { path: path.into(), source }
    }

    /// The message without the leading path of an `Io` or `Path` error, for an error type that
    /// names the file itself (`ImportError`).
    pub fn without_path(&self) -> String {
        match self {
            Error::Io { source, .. } => source.to_string(),
            Error::Path { reason, .. } => reason.clone(),
            other => other.to_string(),
        }
    }

    /// This error prefixed with what was being done.
    pub fn context(self, context: impl Into<String>) -> Error {
        Error::Context { context: context.into(), source: Box::new(self) }
    }
}

impl From<cbd_runtime::Error> for Error {
    fn from(e: cbd_runtime::Error) -> Error {
        Error::Runtime(e)
    }
}

/// The CLI reports errors as one line of text.
impl From<Error> for String {
    fn from(e: Error) -> String {
        e.to_string()
    }
}

pub type Result<T, E = Error> = std::result::Result<T, E>;

/// Most characters of a file's (or the command line's) text quoted in a message.
pub const EXCERPT_CHARS: usize = 40;

/// `text` as a message quotes it: at most [`EXCERPT_CHARS`] characters, control characters escaped
/// (a NUL as `\u{0}`), and the whole length when cut. A field of 300 MB is quoted by its start, not
/// echoed to the terminal whole.
pub fn excerpt(text: &str) -> String {
    excerpt_of(text, EXCERPT_CHARS)
}

/// [`excerpt`] with room for `chars` characters (a parser's message that quotes the file).
pub fn excerpt_of(text: &str, chars: usize) -> String {
    let escape = |c: char| -> String {
        if c.is_control() {
            c.escape_default().collect()
        } else {
            c.to_string()
        }
    };
    let mut out: String = text.chars().take(chars).map(escape).collect();
    if text.chars().nth(chars).is_some() {
        out.push_str(&format!("… ({} bytes)", text.len()));
    }
    out
}

/// The longest error line `cbd` prints, in bytes.
pub const MAX_MESSAGE_BYTES: usize = 1000;

/// `message` as the one line `cbd` prints: line breaks and other control characters become
/// spaces, and a message over [`MAX_MESSAGE_BYTES`] keeps its start (the file, line and column)
/// and says how long it was. Quoting is bounded where it happens ([`excerpt`]); this is the last
/// guard for messages of other libraries (TOML, URDF, JSON parsers).
pub fn one_line(message: &str) -> String {
    let flat: String = message.split(|c: char| c.is_control()).map(str::trim).filter(|p| !p.is_empty()).collect::<Vec<_>>().join(" ");
    if flat.len() <= MAX_MESSAGE_BYTES {
        return flat;
    }
    let mut cut = MAX_MESSAGE_BYTES - 40;
    while !flat.is_char_boundary(cut) {
        cut -= 1;
    }
    format!("{}… ({} bytes in all)", &flat[..cut], flat.len())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Issue 27 item 10: a 300 MB field was echoed whole to stderr; NUL bytes went out raw.
    #[test]
    fn messages_quote_short_excerpts_on_one_line() {
        assert_eq!(excerpt("1.4x"), "1.4x");
        let long = "\0".repeat(1 << 20);
        let e = excerpt(&long);
        assert!(e.starts_with("\\u{0}\\u{0}") && e.ends_with("… (1048576 bytes)") && e.len() < 300, "{e}");
        let m = one_line(&format!("a.toml: TOML parse error at line 5\n  |\n5 | {}\n", "x".repeat(5000)));
        assert!(m.starts_with("a.toml: TOML parse error at line 5 | 5 | xxx") && m.len() <= MAX_MESSAGE_BYTES + 40, "{m}");
        assert!(!m.contains('\n') && m.ends_with("bytes in all)"));
        assert_eq!(one_line("plain"), "plain");
    }
}

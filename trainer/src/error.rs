//! The trainer's one error type, at the bottom of the crate: it names no stage module. Each
//! variant carries what a user needs to find the problem (the file, line, column or field; the
//! joint; the configuration row) and its `Display` is the message the `cbd` command prints. The
//! stage errors (`FitError`, `EvidenceError`, `DhCalibrationError`, `ImportError`, …) stay where
//! their stage is and enter here unchanged as the source of [`Error::Stage`]: each stage's module
//! writes its own `From` conversion (the dependency points from the stage down to this file), and
//! their messages do not change either.

use std::path::PathBuf;

/// Any failure of the trainer's library (the CLI prints it as its `error: …` line).
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
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
    /// A JSON document (a command's `--json` output) that could not be serialised.
    #[error("{0}")]
    JsonOutput(#[source] serde_json::Error),
    /// A URDF chain that cannot be converted to DH (no file: the model file reader adds it).
    #[error("{0}")]
    Urdf(String),
    /// The nominal model is unusable at a measured configuration: names the file and line.
    #[error("{}:{line}: {message}", file.display())]
    NominalAtRow { file: PathBuf, line: u64, message: String },
    /// A row of an input file that a model cannot be evaluated or used at (a target the
    /// calibrated arm cannot reach, a non-finite error): names the file and line.
    #[error("{}:{line}: {message}", file.display())]
    AtLine { file: PathBuf, line: u64, message: String },
    /// Inputs or options that do not fit together (joint counts, a name not known, an empty list,
    /// a command-line value out of range).
    #[error("{0}")]
    InvalidInput(String),
    /// A factorisation failed (non-finite data).
    #[error("{0}")]
    Numerical(String),
    /// A figure could not be drawn.
    #[error("{0}")]
    Plot(String),
    /// A check of the trainer's own work failed (a bug to report, not a bad input).
    #[error("{0}")]
    Internal(String),
    /// A blob could not be decoded.
    #[error(transparent)]
    Decode(#[from] cbd_protocol::DecodeError),
    /// The runtime refused a blob (the runtime's error is `no_std`: not a `std` error source).
    #[error("{0}")]
    Runtime(cbd_runtime::Error),
    /// The runtime could not evaluate configuration `row` (0-based) of a query.
    #[error("configuration {row}: {error}")]
    Evaluate { row: usize, error: cbd_runtime::Error },
    /// A stage's own error, unchanged (its message is the one printed): `stage` names the stage
    /// ("fit", "evidence", "import", …), `source` is its typed error ([`Error::stage_error`]).
    #[error("{source}")]
    Stage {
        stage: &'static str,
        #[source]
        source: Box<dyn std::error::Error + Send + Sync>,
    },
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

    /// A stage's error carried unchanged ([`Error::Stage`]); the stages' `From` conversions call it.
    pub fn stage(stage: &'static str, source: impl std::error::Error + Send + Sync + 'static) -> Error {
        Error::Stage { stage, source: Box::new(source) }
    }

    /// The stage error of type `E` this error carries, also under [`Error::Context`]:
    /// `e.stage_error::<FitError>()`.
    pub fn stage_error<E: std::error::Error + 'static>(&self) -> Option<&E> {
        match self {
            Error::Stage { source, .. } => source.downcast_ref(),
            Error::Context { source, .. } => source.stage_error(),
            _ => None,
        }
    }
}

/// `?` with what was being done: `read(path).context(path.display())?` fails with
/// `path: <the error>`, the error kept as the source.
pub trait Context<T> {
    fn context(self, context: impl std::fmt::Display) -> Result<T>;
}

impl<T, E: Into<Error>> Context<T> for std::result::Result<T, E> {
    fn context(self, context: impl std::fmt::Display) -> Result<T> {
        self.map_err(|e| e.into().context(context.to_string()))
    }
}

impl From<cbd_runtime::Error> for Error {
    fn from(e: cbd_runtime::Error) -> Error {
        Error::Runtime(e)
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
        if c.is_control() || invisible(c) {
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

    /// Issue 29: a stage's error enters unchanged (its message, its type as the source) and is
    /// found again under a context; `?` with a context reads as the CLI's `path: message`.
    #[test]
    fn stage_errors_keep_their_message_and_type() {
        #[derive(Debug, PartialEq, thiserror::Error)]
        #[error("the stage says no")]
        struct StageError;
        let e = Error::stage("test", StageError).context("data.csv");
        assert_eq!(e.to_string(), "data.csv: the stage says no");
        assert_eq!(e.stage_error::<StageError>(), Some(&StageError));
        assert!(e.stage_error::<std::io::Error>().is_none());
        let source = std::error::Error::source(&e).map(|s| s.to_string());
        assert_eq!(source.as_deref(), Some("the stage says no"));
        let r: Result<()> = Err(Error::stage("test", StageError)).context(std::path::Path::new("a.blob").display());
        assert_eq!(r.unwrap_err().to_string(), "a.blob: the stage says no");
    }
}

/// A character that shows as nothing (or moves text) where it is printed: zero-width spaces and
/// joiners, the soft hyphen, bidirectional marks and the byte-order mark. A name holding one looks
/// like another name; messages write it as its escape (`q1\u{200b}`).
pub fn invisible(c: char) -> bool {
    matches!(c, '\u{ad}' | '\u{200b}'..='\u{200f}' | '\u{202a}'..='\u{202e}' | '\u{2060}'..='\u{2064}' | '\u{2066}'..='\u{2069}' | '\u{feff}')
}

/// A refused value echoed as it reads: the shortest text that parses back to exactly `v`, so a
/// value next to an accepted one (`-1.0000000000000002` for a sign) never prints as the accepted
/// one (`-1`). Short values as [`number`] prints them.
pub fn as_written(v: f64) -> String {
    let short = number(v);
    if short.parse::<f64>().ok() == Some(v) || !v.is_finite() {
        return short;
    }
    let plain = format!("{v}");
    if plain.len() <= 24 {
        plain
    } else {
        format!("{v:e}")
    }
}

/// A number as a message prints it: short — as written when that is short (`0.5`, `360`,
/// `1e300`), else in scientific form with five significant digits (`3.6e101`, `3.3333e-1`); `{v}`
/// of 1e300 is 301 digits. NaN and infinities by name.
pub fn number(v: f64) -> String {
    let plain = format!("{v}");
    if !v.is_finite() || v == 0.0 || ((1e-4..1e7).contains(&v.abs()) && plain.len() <= 12) {
        return plain;
    }
    let shortest = format!("{v:e}");
    if shortest.len() <= 10 {
        return shortest;
    }
    let rounded = format!("{v:.4e}");
    let (mantissa, exponent) = rounded.split_once('e').unwrap_or((&rounded, "0"));
    format!("{}e{exponent}", mantissa.trim_end_matches('0').trim_end_matches('.'))
}

#[cfg(test)]
mod number_tests {
    #[test]
    fn numbers_in_messages_are_short() {
        assert_eq!(super::number(1e300), "1e300");
        // Issue 51: a refused value is never echoed as an accepted one.
        assert_eq!(super::as_written(-1.0000000000000002), "-1.0000000000000002");
        assert_eq!(super::as_written(0.99999999999), "0.99999999999");
        assert_eq!(super::as_written(1.000000000000001e300), "1.000000000000001e300");
        assert_eq!(super::as_written(-1.0), "-1");
        assert_eq!(super::as_written(1e300), "1e300");
        assert_eq!(super::excerpt("q1\u{200b}"), "q1\\u{200b}");
        assert_eq!(super::number(-2.5e-300), "-2.5e-300");
        assert_eq!(super::number(0.5), "0.5");
        assert_eq!(super::number(360.0), "360");
        assert_eq!(super::number(f64::NAN), "NaN");
        assert_eq!(super::number(f64::NEG_INFINITY), "-inf");
        assert_eq!(super::number(1.0 / 3.0), "3.3333e-1");
        assert_eq!(super::number(3.5999999999999997e101), "3.6e101");
        assert_eq!(super::number(89.159), "89.159");
    }
}

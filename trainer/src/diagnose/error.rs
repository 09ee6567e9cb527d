//! Why a diagnosis could not be made. Its own file: the failed correction is held as a boxed
//! source (the crate's error), and the conversion into `crate::Error` is written here.

/// Why a diagnosis could not be made.
#[derive(Debug, thiserror::Error)]
pub enum DiagnoseError {
    /// `held_out` rows of the data's `rows` went to the held-out split (0 with a test file).
    #[error("diagnose needs at least 10 training rows, got {got}{}", held_out_note(*rows, *held_out))]
    TooFewRows { got: usize, rows: usize, held_out: usize },
    #[error("the model has {model} task coordinates, the data {train} (test {test})")]
    TaskDimension { model: usize, train: usize, test: usize },
    /// The found effects do not fit in one model's effect list.
    #[error("more than {} effects", cbd_protocol::MAX_EFFECTS)]
    TooManyEffects,
    /// An effect kind the blob cannot hold (a test's) was to be written into the model.
    #[error("{kind} has no blob form")]
    NotInBlob { kind: &'static str },
    /// The nonparametric correction of a table row failed: `on` names the model it corrects;
    /// `source` is the trainer's error (`crate::Error`).
    #[error("CbD on {on}: {source}")]
    Correction {
        on: &'static str,
        #[source]
        source: Box<dyn std::error::Error + Send + Sync>,
    },
}

impl From<DiagnoseError> for crate::Error {
    fn from(e: DiagnoseError) -> crate::Error {
        crate::Error::stage("diagnose", e)
    }
}

/// Issue 27 (messages): "got 2" for a file of 3 rows did not say that one was held out.
fn held_out_note(rows: usize, held_out: usize) -> String {
    match held_out {
        0 => String::new(),
        h => format!(" (the data's {rows} rows less {h} held out for testing; --test FILE holds none out)"),
    }
}

impl DiagnoseError {
    pub(super) fn on_effects(e: impl Into<Box<dyn std::error::Error + Send + Sync>>) -> DiagnoseError {
        DiagnoseError::Correction { on: "nominal + effects", source: e.into() }
    }

    pub(super) fn on_nominal(e: impl Into<Box<dyn std::error::Error + Send + Sync>>) -> DiagnoseError {
        DiagnoseError::Correction { on: "nominal", source: e.into() }
    }
}

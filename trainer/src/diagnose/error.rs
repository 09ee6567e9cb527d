//! Why a diagnosis could not be made. Its own file, free of the crate's error type (the failed
//! correction is held as a boxed source), so `crate::Error` can hold it without an import cycle.

/// Why a diagnosis could not be made.
#[derive(Debug, thiserror::Error)]
pub enum DiagnoseError {
    #[error("diagnose needs at least 10 training rows, got {got}")]
    TooFewRows { got: usize },
    #[error("the model has {model} task coordinates, the data {train} (test {test})")]
    TaskDimension { model: usize, train: usize, test: usize },
    /// The found effects do not fit in one model's effect list.
    #[error("more than {} effects", cbd_protocol::MAX_EFFECTS)]
    TooManyEffects,
    /// The nonparametric correction of a table row failed: `on` names the model it corrects;
    /// `source` is the trainer's error (`crate::Error`).
    #[error("CbD on {on}: {source}")]
    Correction {
        on: &'static str,
        #[source]
        source: Box<dyn std::error::Error + Send + Sync>,
    },
}

impl DiagnoseError {
    pub(super) fn on_effects(e: impl Into<Box<dyn std::error::Error + Send + Sync>>) -> DiagnoseError {
        DiagnoseError::Correction { on: "nominal + effects", source: e.into() }
    }

    pub(super) fn on_nominal(e: impl Into<Box<dyn std::error::Error + Send + Sync>>) -> DiagnoseError {
        DiagnoseError::Correction { on: "nominal", source: e.into() }
    }
}

//! Why a type-II maximum-likelihood search found no hyperparameters: CbD's evidence
//! (`crate::evidence`) and kernel ridge's selection (`baselines::kernel_ridge`) fail in the same
//! two ways, told apart by the search they name.

/// The search that failed, named in its message and as the CLI's stage.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LikelihoodSearch {
    /// CbD's evidence (docs/DESIGN.md §3).
    CbdEvidence,
    /// Kernel ridge's hyperparameters, the peer's own evidence.
    KernelRidge,
}

impl LikelihoodSearch {
    /// The stage [`crate::Error`] reports it under.
    pub fn stage(self) -> &'static str {
        match self {
            LikelihoodSearch::CbdEvidence => "evidence",
            LikelihoodSearch::KernelRidge => "hyperparameters",
        }
    }
}

impl std::fmt::Display for LikelihoodSearch {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            LikelihoodSearch::CbdEvidence => "CbD evidence",
            LikelihoodSearch::KernelRidge => "kernel ridge's hyperparameter search",
        })
    }
}

/// The search could not start, or no setting it tried gave a covariance to score.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LikelihoodSearchError {
    /// Fewer than [`MIN_SEARCH_ROWS`] rows.
    #[error("{0}: {1} rows are too few (need at least {MIN_SEARCH_ROWS})")]
    TooFewRows(LikelihoodSearch, usize),
    /// No start gave a positive-definite covariance.
    #[error(
        "{0}: no start gave a positive-definite covariance (the residual is zero or its rows coincide: no noise to estimate σ from, measured positions are needed)"
    )]
    NoValidSetting(LikelihoodSearch),
}

/// The fewest rows either search takes.
pub const MIN_SEARCH_ROWS: usize = 3;

impl LikelihoodSearchError {
    /// The search that failed.
    pub fn search(&self) -> LikelihoodSearch {
        match self {
            LikelihoodSearchError::TooFewRows(s, _) | LikelihoodSearchError::NoValidSetting(s) => *s,
        }
    }
}

impl From<LikelihoodSearchError> for crate::Error {
    fn from(e: LikelihoodSearchError) -> crate::Error {
        crate::Error::stage(e.search().stage(), e)
    }
}

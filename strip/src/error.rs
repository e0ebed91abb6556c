//! Library error type.

/// Errors of the strip model pipeline and its cache.
#[derive(Debug, thiserror::Error)]
pub enum StripError {
    #[error("parameter `{field}` = {value}: {why}")]
    Param { field: &'static str, value: f64, why: &'static str },
    #[error("numerical failure in {stage}: {detail}")]
    Numeric { stage: &'static str, detail: String },
    #[error("cache file {path}: {detail}")]
    Cache { path: String, detail: String },
    /// The OS error is part of the message, not a `source` (printed once in an error chain).
    #[error("i/o on {path}: {cause}")]
    Io { path: String, cause: std::io::Error },
}

pub type Result<T> = std::result::Result<T, StripError>;

pub(crate) fn numeric(stage: &'static str, detail: impl Into<String>) -> StripError {
    StripError::Numeric { stage, detail: detail.into() }
}

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
    #[error("i/o on {path}: {source}")]
    Io { path: String, source: std::io::Error },
}

pub type Result<T> = std::result::Result<T, StripError>;

pub(crate) fn numeric(stage: &'static str, detail: impl Into<String>) -> StripError {
    StripError::Numeric { stage, detail: detail.into() }
}

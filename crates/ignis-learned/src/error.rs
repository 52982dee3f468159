//! The error type of `ignis-learned`, split by who is at fault.

use std::path::PathBuf;

/// Everything that can go wrong while fitting, learning, synthesising or loading a flame model.
#[derive(Debug, thiserror::Error)]
pub enum LearnedError {
    /// A parameter is out of range; the message names it and the valid range.
    #[error("invalid parameter `{name}`: {reason}")]
    BadParameter { name: &'static str, reason: String },
    /// The input cannot be modelled (no flame, too few frames, ...); the message says what
    /// input would work.
    #[error("unsupported input: {0}")]
    Unsupported(String),
    /// A numerical step failed (e.g. a covariance that is not positive definite).
    #[error("numerical failure: {0}")]
    Numerical(String),
    /// The model file is not a flame model, or was written by another format version.
    #[error("model file {path}: {reason}")]
    BadModelFile { path: PathBuf, reason: String },
    /// Reading or writing the model file failed.
    #[error("I/O on {path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    /// An error from `ignis-core` (sizes, palettes).
    #[error(transparent)]
    Core(#[from] ignis_core::CoreError),
}

impl LearnedError {
    pub(crate) fn bad(name: &'static str, reason: impl Into<String>) -> Self {
        LearnedError::BadParameter {
            name,
            reason: reason.into(),
        }
    }
}

pub type Result<T, E = LearnedError> = std::result::Result<T, E>;

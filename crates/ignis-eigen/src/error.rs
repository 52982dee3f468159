//! The error type of `ignis-eigen`, split by who is at fault (image-rs `ImageError` style).

use std::path::PathBuf;

/// Everything that can go wrong in `ignis-eigen`.
#[derive(Debug, thiserror::Error)]
pub enum EigenError {
    /// A setting is out of range or malformed; the message names it and the valid range.
    #[error("invalid setting `{name}`: {reason}")]
    BadParameter { name: String, reason: String },
    /// A clip cannot be used for training (empty range, range past the end, no pixels
    /// left after masking, zero frames, ...). Always names the clip.
    #[error("clip `{clip}`: {reason}")]
    BadClip { clip: String, reason: String },
    /// A request would exceed a limit (e.g. a data matrix larger than memory); refused
    /// before anything is allocated.
    #[error("limit exceeded: {0}")]
    LimitExceeded(String),
    /// Reading or writing a file failed.
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// The database directory is missing a file, has a malformed manifest, or a checksum
    /// does not match. `file` names the offending file.
    #[error("database {db}: {file}: {reason}")]
    Database {
        db: PathBuf,
        file: String,
        reason: String,
    },
    /// Decoding a clip failed (the message comes from the frame source).
    #[error("clip `{clip}`: decoding failed: {reason}")]
    Decode { clip: String, reason: String },
    /// The PCA failed.
    #[error("PCA: {0}")]
    Pca(String),
    /// Drawing a plot failed.
    #[error("plot {file}: {reason}")]
    Plot { file: String, reason: String },
    /// A scenario file (`ignis eigen animate`) is malformed or does not fit the database.
    /// Displayed as `file:line:column: message`, like a compiler.
    #[error("{}:{line}:{column}: {message}", file.display())]
    Scenario {
        file: PathBuf,
        line: usize,
        column: usize,
        message: String,
    },
    /// An error from `ignis-core` (sizes, frames).
    #[error(transparent)]
    Core(#[from] ignis_core::CoreError),
}

impl EigenError {
    pub(crate) fn bad(name: &str, reason: impl Into<String>) -> Self {
        EigenError::BadParameter {
            name: name.into(),
            reason: reason.into(),
        }
    }
    pub fn clip(clip: &str, reason: impl Into<String>) -> Self {
        EigenError::BadClip {
            clip: clip.into(),
            reason: reason.into(),
        }
    }
    pub(crate) fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        EigenError::Io {
            path: path.into(),
            source,
        }
    }
    /// An error of `ignis_pca::npy` (reading or writing an array file). I/O errors keep
    /// their path; the others name the file in their message.
    pub(crate) fn npy(e: ignis_pca::PcaError) -> Self {
        match e {
            ignis_pca::PcaError::Io { path, source } => EigenError::Io { path, source },
            ignis_pca::PcaError::LimitExceeded { .. } => EigenError::LimitExceeded(e.to_string()),
            other => EigenError::bad("npy", other.to_string()),
        }
    }
}

pub type Result<T, E = EigenError> = std::result::Result<T, E>;

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
    /// Reading footage failed: `what` names the clip or file, `frame` the frame when
    /// known; the reader's own error is the source.
    #[error("{what}: {}", frame.map_or("cannot read the footage".into(), |f| format!("decoding frame {f} failed")))]
    Decode {
        what: String,
        frame: Option<usize>,
        #[source]
        source: Box<dyn std::error::Error + Send + Sync>,
    },
    /// The PCA, or an array file it reads or writes, failed (I/O errors and memory
    /// refusals of `ignis-pca` become [`EigenError::Io`] and [`EigenError::LimitExceeded`]).
    #[error(transparent)]
    Pca(ignis_pca::PcaError),
    /// The PCA kept no component: the training frames do not vary.
    #[error("PCA: no component retained (are all training frames identical?)")]
    NoComponents,
    /// A transition method found no path between two motions (e.g. End Growing did not
    /// join within its step limit); another method, or `auto`, may.
    #[error("{method}: no transition found: {reason}")]
    NoPath {
        method: &'static str,
        reason: String,
    },
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
    /// A footage error seen while using clip `clip`: a decoding error names the clip too.
    pub fn in_clip(self, clip: &str) -> Self {
        match self {
            EigenError::Decode {
                what,
                frame,
                source,
            } if !what.starts_with("clip `") => EigenError::Decode {
                what: format!("clip `{clip}` ({what})"),
                frame,
                source,
            },
            other => other,
        }
    }
    pub(crate) fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        EigenError::Io {
            path: path.into(),
            source,
        }
    }
}

impl From<ignis_pca::PcaError> for EigenError {
    /// I/O errors keep their path; a memory refusal is [`EigenError::LimitExceeded`].
    fn from(e: ignis_pca::PcaError) -> Self {
        match e {
            ignis_pca::PcaError::Io { path, source } => EigenError::Io { path, source },
            ignis_pca::PcaError::LimitExceeded { .. } => EigenError::LimitExceeded(e.to_string()),
            other => EigenError::Pca(other),
        }
    }
}

impl From<crate::transition::TransitionError> for EigenError {
    /// A bad setting stays a bad setting (a bad range names the range); a failed search is
    /// [`EigenError::NoPath`].
    fn from(e: crate::transition::TransitionError) -> Self {
        use crate::transition::TransitionError as T;
        match e {
            T::BadParameter { name, reason } => EigenError::BadParameter { name, reason },
            T::BadRange { .. } => EigenError::bad("range", e.to_string()),
            T::NoPath { method, reason } => EigenError::NoPath { method, reason },
        }
    }
}

pub type Result<T, E = EigenError> = std::result::Result<T, E>;

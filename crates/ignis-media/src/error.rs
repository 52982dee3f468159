//! The error type of `ignis-media`, split by who is at fault (like image-rs's `ImageError`).

use std::path::{Path, PathBuf};

/// Everything that can go wrong while reading or writing media.
#[derive(Debug, thiserror::Error)]
pub enum MediaError {
    /// A parameter is out of range or malformed (empty frame range, crop outside the frame,
    /// zero fps, …); the message names the parameter and what would be valid.
    #[error("invalid parameter `{name}`: {reason}")]
    BadParameter { name: &'static str, reason: String },
    /// The input (or requested output) is of a kind this build cannot handle; `fix` says
    /// what would handle it (e.g. "install ffmpeg", "convert to a PNG sequence").
    #[error("unsupported {what} in {path}: {fix}")]
    Unsupported {
        path: PathBuf,
        what: String,
        fix: String,
    },
    /// A safety limit would be exceeded (frame or sprite sheet too large, …).
    #[error("limit exceeded: {0}")]
    LimitExceeded(String),
    /// Reading or writing a file failed.
    #[error("I/O error on {path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// The input is damaged or not what its name says; `frame` is the index of the frame
    /// being decoded when it happened, if any.
    #[error("cannot decode {path}{}: {msg}", frame.map(|f| format!(" (frame {f})")).unwrap_or_default())]
    Decode {
        path: PathBuf,
        frame: Option<u64>,
        msg: String,
    },
    /// An encoder or muxer failed.
    #[error("cannot encode {path}: {msg}")]
    Encode { path: PathBuf, msg: String },
}

impl MediaError {
    pub(crate) fn bad(name: &'static str, reason: impl Into<String>) -> Self {
        MediaError::BadParameter {
            name,
            reason: reason.into(),
        }
    }
    pub(crate) fn io(path: &Path, source: std::io::Error) -> Self {
        MediaError::Io {
            path: path.to_path_buf(),
            source,
        }
    }
    pub(crate) fn decode(path: &Path, frame: Option<u64>, msg: impl Into<String>) -> Self {
        MediaError::Decode {
            path: path.to_path_buf(),
            frame,
            msg: msg.into(),
        }
    }
    pub(crate) fn encode(path: &Path, msg: impl Into<String>) -> Self {
        MediaError::Encode {
            path: path.to_path_buf(),
            msg: msg.into(),
        }
    }
    pub(crate) fn unsupported(
        path: &Path,
        what: impl Into<String>,
        fix: impl Into<String>,
    ) -> Self {
        MediaError::Unsupported {
            path: path.to_path_buf(),
            what: what.into(),
            fix: fix.into(),
        }
    }
}

impl From<ignis_core::CoreError> for MediaError {
    fn from(e: ignis_core::CoreError) -> Self {
        match e {
            ignis_core::CoreError::BadParameter { name, reason } => {
                MediaError::BadParameter { name, reason }
            }
            ignis_core::CoreError::LimitExceeded(m) => MediaError::LimitExceeded(m),
            ignis_core::CoreError::SizeMismatch(m) => MediaError::bad("frame", m),
        }
    }
}

pub type Result<T, E = MediaError> = std::result::Result<T, E>;

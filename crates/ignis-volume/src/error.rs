//! The error type of `ignis-volume`, split by who is at fault.

/// Everything that can go wrong in `ignis-volume`.
#[derive(Debug, thiserror::Error)]
pub enum VolumeError {
    /// A setting is out of range or malformed; `field` is its path in the fire file
    /// (e.g. `fire[0].curve.points`, `render.slice_spacing`).
    #[error("invalid `{field}`: {reason}")]
    BadParameter { field: String, reason: String },
    /// The fire file is not valid TOML or has the wrong shape.
    #[error("fire file: {0}")]
    Parse(String),
    /// A profile image could not be loaded.
    #[error("`{field}`: cannot load profile image {path}: {reason}")]
    Image {
        field: String,
        path: std::path::PathBuf,
        reason: String,
    },
    /// The estimated work or memory of a render is past a documented limit
    /// ([`crate::render::MAX_SAMPLES`], [`crate::render::MAX_CANDIDATES`]).
    #[error("too much work: {0}")]
    LimitExceeded(String),
    /// A frame-level error from `ignis-core` (size limits, bloom settings).
    #[error(transparent)]
    Core(#[from] ignis_core::CoreError),
}

impl VolumeError {
    /// A [`VolumeError::BadParameter`] for `field`.
    pub fn bad(field: impl Into<String>, reason: impl Into<String>) -> Self {
        VolumeError::BadParameter {
            field: field.into(),
            reason: reason.into(),
        }
    }
}

pub type Result<T, E = VolumeError> = std::result::Result<T, E>;

//! The error type of `ignis-flow`, split by who is at fault.

/// Everything that can go wrong in `ignis-flow`.
#[derive(Debug, thiserror::Error)]
pub enum FlowError {
    /// A parameter is out of range or malformed; the message names it and the valid range.
    #[error("invalid parameter `{name}`: {reason}")]
    BadParameter { name: &'static str, reason: String },
    /// Two inputs that must agree in size do not.
    #[error("size mismatch: {0}")]
    SizeMismatch(String),
    /// An input frame or field holds values flow cannot use (NaN or infinite pixels).
    #[error("unusable input: {0}")]
    BadInput(String),
    /// A frame-level error from `ignis-core` (e.g. a size beyond its limits).
    #[error(transparent)]
    Core(#[from] ignis_core::CoreError),
}

impl FlowError {
    pub(crate) fn bad(name: &'static str, reason: impl Into<String>) -> Self {
        FlowError::BadParameter {
            name,
            reason: reason.into(),
        }
    }
}

/// `Result` with [`FlowError`].
pub type Result<T, E = FlowError> = std::result::Result<T, E>;

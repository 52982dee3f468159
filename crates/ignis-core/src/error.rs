//! The error type of `ignis-core`, split by who is at fault.

/// Everything that can go wrong in `ignis-core`.
#[derive(Debug, thiserror::Error)]
pub enum CoreError {
    /// A parameter is out of range or malformed; the message names it and the valid range.
    #[error("invalid parameter `{name}`: {reason}")]
    BadParameter { name: &'static str, reason: String },
    /// A request exceeds a safety limit (e.g. a frame too large to allocate).
    #[error("limit exceeded: {0}")]
    LimitExceeded(String),
    /// Two inputs that must agree in size do not.
    #[error("size mismatch: {0}")]
    SizeMismatch(String),
}

impl CoreError {
    pub fn bad(name: &'static str, reason: impl Into<String>) -> Self {
        CoreError::BadParameter {
            name,
            reason: reason.into(),
        }
    }
}

pub type Result<T, E = CoreError> = std::result::Result<T, E>;

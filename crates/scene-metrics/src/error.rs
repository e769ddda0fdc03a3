//! The crate's error type: every failure names the setting or file it concerns.

use std::path::PathBuf;

/// Errors of the metrics: inputs of the wrong shape or range, and pretrained weights.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// A file could not be read.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying error.
        source: std::io::Error,
    },
    /// A pretrained network's weights file is not a safetensors file, or a tensor in it is
    /// missing, misshapen or out of range.
    #[error("weights {path}: {why}")]
    Weights {
        /// The weights file.
        path: PathBuf,
        /// Which tensor is wrong and what was expected.
        why: String,
    },
    /// An input or setting is out of range.
    #[error("invalid {what}: {why}")]
    Invalid {
        /// The input or setting.
        what: String,
        /// What was expected.
        why: String,
    },
    /// An error from swd-loss.
    #[error(transparent)]
    Swd(#[from] swd_loss::Error),
    /// A tensor operation failed.
    #[error(transparent)]
    Candle(#[from] candle_core::Error),
}

/// The crate's result type.
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// An [`Error::Invalid`] for `what`.
pub(crate) fn invalid(what: impl Into<String>, why: impl Into<String>) -> Error {
    Error::Invalid {
        what: what.into(),
        why: why.into(),
    }
}

/// An [`Error::Io`] for `path`.
pub(crate) fn io_error(path: impl Into<PathBuf>) -> impl FnOnce(std::io::Error) -> Error {
    let path = path.into();
    move |source| Error::Io { path, source }
}

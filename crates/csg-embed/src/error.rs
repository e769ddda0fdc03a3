//! The error type of this crate.

use std::borrow::Cow;

/// Everything that can go wrong when building an embedding.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// An argument was out of its domain (a zero-sized grid, an empty frequency list, ...).
    #[error("invalid {what}: {why}")]
    Invalid {
        /// Which argument.
        what: &'static str,
        /// Why it was rejected.
        why: Cow<'static, str>,
    },
    /// An error raised by candle.
    #[error(transparent)]
    Candle(#[from] candle_core::Error),
}

/// This crate's result type.
pub type Result<T> = std::result::Result<T, Error>;

pub(crate) fn invalid(what: &'static str, why: impl Into<Cow<'static, str>>) -> Error {
    Error::Invalid {
        what,
        why: why.into(),
    }
}

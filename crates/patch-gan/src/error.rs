//! The error type of this crate.

use std::borrow::Cow;

/// Everything that can go wrong when building or running the networks of this crate.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// An argument or configuration value was out of its domain.
    #[error("invalid {what}: {why}")]
    Invalid {
        /// Which argument or field.
        what: &'static str,
        /// Why it was rejected.
        why: Cow<'static, str>,
    },
    /// The gradient penalty needs candle to keep the graph of its backward pass, which it only does
    /// when the environment variable `CANDLE_GRAD_DO_NOT_DETACH` is set.
    #[error(
        "second-order gradients are disabled: set CANDLE_GRAD_DO_NOT_DETACH=1 before the first \
         backward pass (candle reads it once per thread)"
    )]
    SecondOrderDisabled,
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

/// Lets the layers report this crate's errors through candle's `Module` trait.
impl From<Error> for candle_core::Error {
    fn from(e: Error) -> Self {
        match e {
            Error::Candle(inner) => inner,
            other => candle_core::Error::wrap(other),
        }
    }
}

//! The crate's error type: each variant says whose fault it is and carries the context a user
//! needs to fix it (which argument, what was expected, what was given).

use std::borrow::Cow;
use std::path::PathBuf;

/// Errors of swd-loss.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// A caller passed arguments that do not fit together (ranks, feature dimensions, empty
    /// sets, zero projections, batch sizes, layer weights).
    #[error("invalid argument `{what}`: {why}")]
    InvalidArgument {
        /// The argument or field at fault.
        what: &'static str,
        /// What was expected and what was given.
        why: Cow<'static, str>,
    },
    /// Values that must be finite are not (NaN or infinite); sorting them would be meaningless.
    #[error("`{what}` holds NaN or infinite values")]
    NonFinite {
        /// Which input holds them (e.g. `"x"`, `"generated layer 2"`).
        what: Cow<'static, str>,
    },
    /// An I/O error on a named file (e.g. a VGG-19 weights file).
    #[error("{}: {source}", path.display())]
    Io {
        /// The file being read.
        path: PathBuf,
        /// The underlying I/O error.
        #[source]
        source: std::io::Error,
    },
    /// An error from candle (device, dtype, tensor operation, missing or misshapen weights).
    #[error(transparent)]
    Candle(#[from] candle_core::Error),
}

/// The crate's result type.
pub type Result<T> = std::result::Result<T, Error>;

/// Builds an [`Error::InvalidArgument`].
pub(crate) fn invalid(what: &'static str, why: impl Into<Cow<'static, str>>) -> Error {
    Error::InvalidArgument {
        what,
        why: why.into(),
    }
}

//! The crate's error type: each variant says whose fault it is and carries the context needed to
//! fix it (the argument or file field at fault, what was expected, what was given).

use std::borrow::Cow;
use std::path::PathBuf;

/// Errors of volrender.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// A caller passed arguments that do not fit together (shapes, counts, degenerate cameras).
    #[error("invalid argument `{what}`: {why}")]
    InvalidArgument {
        /// The argument at fault.
        what: &'static str,
        /// What was expected and what was given.
        why: Cow<'static, str>,
    },
    /// A volume holds values the renderer cannot use: NaN or infinite values, negative physical
    /// density, or values beyond [`MAX_VOLUME_VALUE`](crate::MAX_VOLUME_VALUE) in magnitude.
    #[error("invalid volume values: {count} bad value(s), first at {first}: {why}")]
    InvalidVolume {
        /// How many values are bad.
        count: usize,
        /// Where the first one is, e.g. `volume 0, channel 0 (sigma), voxel (d=1, h=2, w=3) = NaN`.
        first: String,
        /// Which rule they break.
        why: &'static str,
    },
    /// A camera file (`transforms.json`) does not hold what the format requires.
    #[error("{}: invalid transforms.json: {why}", path.display())]
    InvalidTransforms {
        /// The file that was read.
        path: PathBuf,
        /// What was wrong, naming the frame and field.
        why: String,
    },
    /// The operation is not available for this input (device, dtype).
    #[error("unsupported {what}: {why}")]
    Unsupported {
        /// The capability asked for.
        what: &'static str,
        /// Why it is unsupported and what to do about it.
        why: Cow<'static, str>,
    },
    /// An I/O error on a named file.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file being read or written.
        path: PathBuf,
        /// The underlying I/O error.
        #[source]
        source: std::io::Error,
    },
    /// An image encoder failed (PNG or EXR) on a named file.
    #[error("{}: cannot encode {format}: {why}", path.display())]
    Encode {
        /// The file being written.
        path: PathBuf,
        /// `"png"` or `"exr"`.
        format: &'static str,
        /// The encoder's message.
        why: String,
    },
    /// An error from radiance-volume (occupancy grids, volume construction).
    #[error(transparent)]
    Volume(#[from] radiance_volume::Error),
    /// An error from candle (device, dtype or tensor operation).
    #[error(transparent)]
    Candle(#[from] candle_core::Error),
}

/// Result alias of volrender.
pub type Result<T> = std::result::Result<T, Error>;

/// Builds an [`Error::InvalidArgument`].
pub(crate) fn invalid(what: &'static str, why: impl Into<Cow<'static, str>>) -> Error {
    Error::InvalidArgument {
        what,
        why: why.into(),
    }
}

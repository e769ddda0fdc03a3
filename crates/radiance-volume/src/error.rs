//! The crate's error type: each variant says whose fault it is and carries the context a user
//! needs to fix it (the file, the field, what was expected).

use std::borrow::Cow;
use std::path::PathBuf;

/// Errors of radiance-volume.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// A caller passed arguments that do not fit together (shapes, channel counts, boxes).
    #[error("invalid argument `{what}`: {why}")]
    InvalidArgument {
        /// The argument or field at fault.
        what: &'static str,
        /// What was expected and what was given.
        why: Cow<'static, str>,
    },
    /// A file's content is not what the format requires.
    #[error("{}: invalid {format} file: {why}", path.display())]
    InvalidFile {
        /// The file that was read.
        path: PathBuf,
        /// The format that was expected (e.g. `"volgen safetensors volume"`).
        format: &'static str,
        /// What was wrong, naming the field.
        why: String,
    },
    /// Values that must be finite are not (NaN or infinite).
    #[error("{what}: {count} non-finite value(s), first at {first}")]
    NonFinite {
        /// What holds the values (a file, a channel, a volume).
        what: String,
        /// How many values are NaN or infinite.
        count: usize,
        /// Where the first one is, e.g. `channel 0 (sigma), voxel (d=1, h=2, w=3)`.
        first: String,
    },
    /// The operation needs a format or feature that is not compiled in or not supported.
    #[error("unsupported {format}: {why}")]
    Unsupported {
        /// The format or capability.
        format: &'static str,
        /// Why it is unsupported and what to do about it.
        why: Cow<'static, str>,
    },
    /// An I/O error on a named file.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file or directory being read or written.
        path: PathBuf,
        /// The underlying I/O error.
        #[source]
        source: std::io::Error,
    },
    /// Writing a file of known size failed part-way (a full disk, a file-size limit). The write
    /// went to a temporary file, which is removed: a file already at `path` is unchanged.
    #[error(
        "{}: could not write its {bytes} bytes ({source}); a previous version of the file, if \
         any, is unchanged",
        path.display()
    )]
    Write {
        /// The file being written (its final name).
        path: PathBuf,
        /// The size of the whole file.
        bytes: u64,
        /// The underlying I/O error.
        #[source]
        source: std::io::Error,
    },
    /// An error from candle (device, dtype or tensor operation).
    #[error(transparent)]
    Candle(#[from] candle_core::Error),
}

/// Result alias of radiance-volume.
pub type Result<T> = std::result::Result<T, Error>;

/// Builds an [`Error::InvalidArgument`].
pub(crate) fn invalid(what: &'static str, why: impl Into<Cow<'static, str>>) -> Error {
    Error::InvalidArgument {
        what,
        why: why.into(),
    }
}

/// Wraps an I/O error with the path it happened on.
pub(crate) fn io_error(path: impl Into<PathBuf>) -> impl FnOnce(std::io::Error) -> Error {
    let path = path.into();
    move |source| Error::Io { path, source }
}

/// Builds the error for a finite value that a half-float export cannot store (|v| > 65504).
#[cfg(any(feature = "vdb", feature = "exr"))]
pub(crate) fn beyond_half(what: &str, value: f32, at: &str) -> Error {
    invalid(
        "half",
        format!(
            "{what} holds {value} at {at}, beyond the half-float range (±65504); export full \
             floats instead"
        ),
    )
}

//! The crate's error type: every failure names the file, frame or setting it concerns.

use std::path::PathBuf;

/// Errors of writing, loading and resizing datasets and of building scenes.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// A file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying error.
        source: std::io::Error,
    },
    /// A dataset is malformed: `frame` names the frame (its `file_path`, or its index) when the
    /// problem is in one frame.
    #[error("{path}: {}{why}", frame.as_ref().map(|f| format!("frame {f}: ")).unwrap_or_default())]
    Dataset {
        /// The dataset file (usually `transforms.json`) or the image concerned.
        path: PathBuf,
        /// The frame concerned, if any.
        frame: Option<String>,
        /// What is wrong and what was expected.
        why: String,
    },
    /// A setting or argument is out of range.
    #[error("invalid {what}: {why}")]
    Invalid {
        /// The setting.
        what: String,
        /// What was expected.
        why: String,
    },
    /// An error from radiance-volume.
    #[error(transparent)]
    Volume(#[from] radiance_volume::Error),
    /// An error from volrender.
    #[error(transparent)]
    Render(#[from] volrender::Error),
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

//! Errors of mesh extraction and writing.

use std::borrow::Cow;
use std::path::PathBuf;

/// What went wrong making or writing a mesh.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// An argument is out of its range; names the argument and what was expected.
    #[error("invalid argument `{what}`: {why}")]
    InvalidArgument {
        /// The argument at fault.
        what: &'static str,
        /// What was expected and what was given.
        why: Cow<'static, str>,
    },
    /// The volume has no surface at the asked level (empty, or all matter below it).
    #[error("no surface: {why}")]
    NoSurface {
        /// What the volume holds, and what to try.
        why: String,
    },
    /// The output file's extension names no format this crate writes.
    #[error("{}: unknown mesh format (expected .glb, .gltf, .ply or .obj)", path.display())]
    UnknownFormat {
        /// The file asked for.
        path: PathBuf,
    },
    /// Reading the volume or writing the file failed.
    #[error(transparent)]
    Volume(#[from] radiance_volume::Error),
    /// A tensor operation failed.
    #[error(transparent)]
    Tensor(#[from] candle_core::Error),
}

/// A `Result` with this crate's [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;

pub(crate) fn invalid(what: &'static str, why: impl Into<Cow<'static, str>>) -> Error {
    Error::InvalidArgument {
        what,
        why: why.into(),
    }
}

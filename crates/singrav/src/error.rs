//! The crate's error type: every failure names the file, frame or setting it concerns.

use std::path::PathBuf;

/// Errors of dataset loading, training, checkpoints, sampling and metrics.
#[derive(Debug, thiserror::Error)]
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
    /// A checkpoint is missing, malformed or does not match the configuration.
    #[error("checkpoint {path}: {why}")]
    Checkpoint {
        /// The checkpoint file or directory.
        path: PathBuf,
        /// What is wrong.
        why: String,
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
    /// A setting or argument is out of range.
    #[error("invalid {what}: {why}")]
    Invalid {
        /// The setting.
        what: String,
        /// What was expected.
        why: String,
    },
    /// Training diverged (a loss became NaN or infinite).
    #[error("training diverged at scale {scale}, step {step}: {what} is {value}")]
    Diverged {
        /// The scale (1-based).
        scale: usize,
        /// The step within the scale.
        step: usize,
        /// The loss that went bad.
        what: &'static str,
        /// Its value.
        value: f32,
    },
    /// An error from radiance-volume.
    #[error(transparent)]
    Volume(#[from] radiance_volume::Error),
    /// An error from volrender.
    #[error(transparent)]
    Render(#[from] volrender::Error),
    /// An error from patch-gan.
    #[error(transparent)]
    Gan(#[from] patch_gan::Error),
    /// An error from swd-loss.
    #[error(transparent)]
    Swd(#[from] swd_loss::Error),
    /// An error from csg-embed.
    #[error(transparent)]
    Csg(#[from] csg_embed::Error),
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

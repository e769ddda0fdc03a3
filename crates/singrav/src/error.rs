//! The crate's error type: every failure names the file, frame or setting it concerns.

use std::path::PathBuf;

/// Errors of dataset loading, training, checkpoints, sampling and metrics.
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
    /// Training diverged (a loss or a gradient became NaN or infinite). Nothing of the bad
    /// iteration was saved: the run directory's last checkpoint is intact.
    #[error(
        "training diverged at scale {scale}, iteration {step}: {what}; nothing of this \
         iteration was saved, the run directory keeps its last checkpoint"
    )]
    Diverged {
        /// The scale (1-based).
        scale: usize,
        /// The iteration within the scale (0-based).
        step: usize,
        /// What went bad and its value, e.g. `critic loss is NaN`.
        what: String,
    },
    /// An optimiser was given a gradient with a NaN or infinite element; no variable was
    /// updated. Training reports it as [`Error::Diverged`].
    #[error("the gradient of {parameter} is not finite (its sum is {value})")]
    NonFiniteGradient {
        /// The variable's name.
        parameter: String,
        /// The sum of the gradient's elements.
        value: f32,
    },
    /// A computation of a training run failed (a tensor operation, the renderer, a device's
    /// driver): where in the run, and the error.
    #[error("scale {scale}, {at}: {source}")]
    Training {
        /// The scale (1-based).
        scale: usize,
        /// Where in the scale: `set-up`, `iteration 12`, `pictures`.
        at: String,
        /// The error.
        source: Box<Error>,
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
    /// An error from rgbd-dataset (loading or making a dataset).
    #[error(transparent)]
    Dataset(#[from] rgbd_dataset::Error),
    /// An error from scene-metrics.
    #[error(transparent)]
    Metrics(#[from] scene_metrics::Error),
    /// An error from volume-fit.
    #[error(transparent)]
    Fit(#[from] volume_fit::Error),
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

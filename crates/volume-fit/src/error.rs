//! The crate's error type: every failure names the setting or input it concerns.

/// Errors of a direct fit.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
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
    /// An error from rgbd-dataset (the views to fit).
    #[error(transparent)]
    Dataset(#[from] rgbd_dataset::Error),
    /// An error from scene-metrics.
    #[error(transparent)]
    Metrics(#[from] scene_metrics::Error),
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

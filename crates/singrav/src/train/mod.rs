//! Coarse-to-fine training: each scale trains its generator (earlier scales frozen) against its
//! patch critic, with the reconstruction loss on the fixed noise, SinGAN-style noise amplitudes,
//! checkpoints per scale and every few minutes, a JSON-lines loss log and a picture of samples
//! after each scale.

mod colour;
mod critic;
mod final_scale;
mod fitted;
mod height_profile;
mod log;
mod losses;
mod prepare;
mod reconstruction_fit;
mod run;
mod sample_opacity;
mod stage;
mod texture;
mod volume_scale;

use std::path::PathBuf;

pub use fitted::fit_training_target;
pub use log::{read_log, LogLine};
pub use losses::{LossTerm, StepLosses};
pub use prepare::{beyond_the_cube, prepare, FitMade, RunFit, RunInputs};
pub use run::{train, TrainOutcome, Trainer};

/// The process's peak resident memory in MiB (Linux `VmHWM`), if the OS reports it; recorded
/// per scale in checkpoints.
///
/// ```
/// if let Some(mib) = singrav::train::peak_memory_mib() {
///     assert!(mib > 0.0);
/// }
/// ```
pub fn peak_memory_mib() -> Option<f64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kib: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib / 1024.0)
}

/// How [`train`] runs, beside its configuration: settings that do not change what is trained,
/// so the checkpoint does not record them and a resumed run may give them differently.
///
/// ```
/// let resume = singrav::train::RunOptions { resume: true, ..Default::default() };
/// assert!(resume.vgg19_weights.is_none());
/// ```
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct RunOptions {
    /// Continue from the run directory's checkpoint (which must have been made with the same
    /// configuration); without it, a directory holding a checkpoint is refused. An existing
    /// directory without a checkpoint yet (a run killed before its first one) starts from the
    /// beginning; a directory that does not exist is an error.
    pub resume: bool,
    /// The VGG-19 weights (safetensors with torchvision's names; docs/swd-loss.md shows how to
    /// convert them) for a configuration whose `losses.swd_features` is
    /// [`crate::SwdFeatures::Vgg19`]; required then, refused otherwise.
    pub vgg19_weights: Option<PathBuf>,
    /// A directly fitted volume (see [`volume_fit`]) for a configuration that compares with
    /// one ([`TrainConfig::compares_with_fit`](crate::TrainConfig::compares_with_fit)), refused
    /// otherwise. Without one such a run fits the training views itself first
    /// ([`TrainConfig::fit_config`](crate::TrainConfig::fit_config); `tiny`'s takes about
    /// 10 s), and a resumed run uses its own copy ([`RunDir::fitted`](crate::RunDir::fitted)).
    pub fitted_volume: Option<PathBuf>,
    /// Steps of the fit a run makes when it compares with a fitted volume and is given none
    /// (default: the fit's own budget).
    pub fit_steps: Option<usize>,
    /// A fit of the views without depth for a run with `run.depth_from_fit`, whose rendered
    /// depth it trains on. Without one such a run fits one itself first
    /// ([`TrainConfig::depth_fit_config`](crate::TrainConfig::depth_fit_config)), and a resumed
    /// run uses its own copy ([`RunDir::depth_fit`](crate::RunDir::depth_fit)).
    pub depth_fit: Option<PathBuf>,
    /// Steps of that fit (default: the fit's own budget).
    pub depth_fit_steps: Option<usize>,
    /// Test hook: before iteration `.1` (0-based) of scale `.0`, every weight of that scale's
    /// generator becomes NaN, so tests can check that a divergence stops the run at once and
    /// leaves the last checkpoint intact.
    #[doc(hidden)]
    pub poison: Option<(usize, usize)>,
}

/// What an observer tells the trainer after a step.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Control {
    /// Go on.
    Continue,
    /// Stop now, without writing anything further (as if the process were killed); the last
    /// checkpoint stays as it is.
    Stop,
}

/// What just happened, for progress display.
#[derive(Debug, Clone, PartialEq)]
pub enum Event {
    /// An iteration finished.
    Step,
    /// A checkpoint was written.
    Checkpoint(PathBuf),
    /// A scale finished; its picture of samples is at the path.
    ScaleDone(PathBuf),
    /// The fit of the finished reconstruction to the views
    /// ([`crate::config::Schedule::reconstruction_fit_steps`]) starts.
    ReconstructionFitting,
    /// The finished reconstruction was fitted to the views
    /// ([`crate::config::Schedule::reconstruction_fit_steps`]); the progress's `scale_seconds` is the
    /// fit's time, `batch_psnr` its last ray batch's colour PSNR in dB.
    ReconstructionFitted {
        /// The last step's batch PSNR (dB).
        batch_psnr: f64,
    },
}

/// Progress reported to the observer.
#[derive(Debug, Clone)]
pub struct Progress {
    /// The scale in training (1-based).
    pub scale: usize,
    /// The number of scales N.
    pub scales: usize,
    /// Iterations done in this scale.
    pub iteration: usize,
    /// Iterations per scale.
    pub iterations: usize,
    /// The last iteration's losses.
    pub losses: StepLosses,
    /// Seconds spent in this scale so far.
    pub scale_seconds: f64,
    /// Seconds of training so far, over all scales (including before a resume).
    pub total_seconds: f64,
    /// What happened.
    pub event: Event,
}

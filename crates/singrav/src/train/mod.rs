//! Coarse-to-fine training: each scale trains its generator (earlier scales frozen) against its
//! patch critic, with the reconstruction loss on the fixed noise, SinGAN-style noise amplitudes,
//! checkpoints per scale and every few minutes, a JSON-lines loss log and a picture of samples
//! after each scale.

mod colour;
mod concurrent;
mod critic;
mod final_scale;
mod fitted;
mod height_profile;
mod log;
mod reconstruction_fit;
mod run;
mod sample_opacity;
mod texture;
mod volume_scale;

use std::path::PathBuf;

use serde::Serialize;

pub use run::{train, TrainOutcome};

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
    /// convert them) for a configuration whose `swd_features` is
    /// [`crate::SwdFeatures::Vgg19`]; required then, refused otherwise.
    pub vgg19_weights: Option<PathBuf>,
    /// A directly fitted volume (see [`crate::fit`]) for a configuration whose
    /// `lambda_fitted` or `lambda_volume_critic` is positive, refused otherwise. Without one
    /// such a run fits the training views itself first
    /// ([`crate::fit::FitConfig::for_training`]; `tiny`'s takes about 10 s), and a resumed run
    /// uses its own copy (`fitted.safetensors`).
    pub fitted_volume: Option<PathBuf>,
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

/// The losses of one iteration (means over its steps); `None` where a term was not computed.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct StepLosses {
    /// Critic loss `mean D(fake) - mean D(real)` (before the penalty).
    pub critic: Option<f32>,
    /// Gradient penalty (weighted).
    pub penalty: Option<f32>,
    /// Generator adversarial loss `-mean D(fake)`.
    pub adversarial: Option<f32>,
    /// Weighted colour reconstruction `lambda_c * mse`.
    pub color: f32,
    /// Weighted depth reconstruction `lambda_d * mse`.
    pub depth: Option<f32>,
    /// Weighted sliced Wasserstein texture loss (last scale).
    pub swd: Option<f32>,
    /// Weighted 3D comparison of the reconstruction with the fitted volume (3D scales of runs
    /// with `lambda_fitted > 0`).
    pub fitted: Option<f32>,
    /// Weighted opacity reconstruction `lambda_opacity * mse(opacity, alpha)` (3D scales of
    /// runs with `lambda_opacity > 0`).
    pub opacity: Option<f32>,
    /// Weighted colour-distribution loss of the generated scenes (3D scales' adversarial
    /// iterations of runs with `lambda_colour > 0`).
    pub colour_distribution: Option<f32>,
    /// Weighted chroma-distribution loss of the generated scenes (3D scales' adversarial
    /// iterations of runs with `lambda_chroma > 0`).
    pub chroma_distribution: Option<f32>,
    /// Weighted height-profile loss of the generated scenes (3D scales' adversarial iterations
    /// of runs with `lambda_height_profile > 0`).
    pub height_profile: Option<f32>,
    /// Weighted binary-opacity prior of the generated scenes (3D scales' adversarial iterations
    /// of runs with `lambda_opacity_binary > 0`).
    pub opacity_binary: Option<f32>,
    /// Weighted opacity-distribution loss of the generated scenes (3D scales' adversarial
    /// iterations of runs with `lambda_opacity_distribution > 0`).
    pub opacity_distribution: Option<f32>,
    /// The 3D critic's loss `mean D3(fake) - mean D3(fitted)` (3D scales' adversarial
    /// iterations of runs with `lambda_volume_critic > 0`).
    pub volume_critic: Option<f32>,
    /// The 3D critic's gradient penalty (weighted).
    pub volume_penalty: Option<f32>,
    /// The generator's weighted adversarial loss against the 3D critic.
    pub volume_adversarial: Option<f32>,
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
    /// ([`crate::TrainConfig::reconstruction_fit_steps`]) starts.
    ReconstructionFitting,
    /// The finished reconstruction was fitted to the views
    /// ([`crate::TrainConfig::reconstruction_fit_steps`]); the progress's `scale_seconds` is the
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

//! The last step of a run with `schedule.reconstruction_fit_steps`: a direct fit of the finished V* to
//! the training views, every network frozen, kept as the reconstruction's detail.
//!
//! The pyramid's V* is what one convolutional network per scale makes of the upsampled coarser
//! volume, and that holds it below a direct fit of its own grid (docs/journal/2026-11-training-quality.md, "Where V*'s
//! 3 dB go"); every recipe that pulled V* nearer during training cost the samples. Fitting
//! after training gives V* a direct fit's per-voxel freedom, starting from what the pyramid
//! made (so voxels no view sees keep the pyramid's values), without touching a generator.

use radiance_volume::Aabb;
use volrender::Sampler;

use crate::error::Result;
use crate::{SinGrav, TrainConfig};
use rgbd_dataset::Dataset;
use volume_fit::{fit_volume_from, FitBudget, FitConfig};

/// What the fit of the reconstruction did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct ReconstructionFit {
    /// Wall-clock seconds of the fit.
    pub seconds: f64,
    /// The colour PSNR (dB) of the last step's ray batch.
    pub batch_psnr: f64,
}

/// The fit's settings for `config`'s finest 3D scale: [`TrainConfig::fit_config`]'s rates and
/// renderer on the model's cube (the dataset is already in it), at that scale's own grid,
/// without growth, with every voxel kept live so the fitted raw values render as the fit
/// rendered them (the occupancy mask would empty voxels whose raw values stay), and training's
/// own reconstruction loss: its weights of colour, opacity and depth, depth in units of
/// `depth_norm` as training measures it (the fit measures world units), and its renderer's
/// samples. A post-activated grid fitted at other sample positions than the model renders at
/// can hold edges that only those positions see.
fn fit_config(config: &TrainConfig, depth_norm: f32) -> FitConfig {
    let size = config.pyramid.volume_sizes.last().copied().unwrap_or(1);
    FitConfig {
        size,
        start_size: size,
        budget: FitBudget::Steps(config.schedule.reconstruction_fit_steps),
        occupancy_every: 0,
        aabb: Aabb::CUBE,
        lambda_color: config.losses.rgb as f32,
        lambda_opacity: config.losses.opacity as f32,
        lambda_depth: config.losses.depth as f32 / (depth_norm * depth_norm),
        sampler: Sampler::Uniform {
            samples: config.pyramid.samples.last().copied().unwrap_or(1),
        },
        ..config.fit_config()
    }
}

/// Fits `model`'s reconstruction to every view of `dataset` (in the model's cube) for
/// `config.schedule.reconstruction_fit_steps` steps and sets the difference as its detail; `depth_norm`
/// is what training divides depth by.
pub(super) fn fit_reconstruction(
    model: &mut SinGrav,
    config: &TrainConfig,
    dataset: &Dataset,
    depth_norm: f32,
) -> Result<ReconstructionFit> {
    let v_star = model.reconstruct()?;
    let views: Vec<usize> = (0..dataset.len()).collect();
    let mut batch_psnr = f64::NAN;
    let fitted = fit_volume_from(
        dataset,
        &views,
        &fit_config(config, depth_norm),
        &v_star.squeeze(0)?,
        &mut |progress| batch_psnr = progress.batch_psnr,
    )?;
    let detail = (fitted.raw.to_device(v_star.device())?.unsqueeze(0)? - &v_star)?;
    model.set_reconstruction_detail(detail)?;
    Ok(ReconstructionFit {
        seconds: fitted.seconds,
        batch_psnr,
    })
}

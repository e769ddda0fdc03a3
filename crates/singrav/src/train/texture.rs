//! The last scale's sliced Wasserstein texture loss and the features it compares: the
//! weights-free patch pyramid, or VGG-19 (the paper's choice) when the user supplies weights.

use std::path::Path;

use candle_core::{Device, Tensor};
use rand::Rng;
use swd_loss::{
    FeatureExtractor, FeatureMap, PatchPyramid, PatchPyramidConfig, Points, Slices, TextureLoss,
    TextureLossConfig, TextureTarget, Vgg19, Vgg19Config,
};

use super::volume_scale::select;
use crate::config::{SwdFeatures, TrainConfig};
use crate::error::{invalid, Error, Result};

/// The most levels of the weights-free patch pyramid the SWD loss compares.
const SWD_LEVELS: usize = 3;

/// Patches per pyramid level one evaluation of the patch-pyramid SWD loss compares: a random
/// subset drawn at every call, for the generated and for the real images. With
/// [`SWD_SLICES`] directions it follows the expected gradient more closely than all patches
/// along 64 directions did (relative error 0.23 against 0.31 at 320^2, 0.19 against 0.32 at
/// 108^2), at a third of their time at 320^2 and about the same at 108^2 (docs/swd-loss.md,
/// "Random patches").
const SWD_POINTS: usize = 4096;

/// Directions per level of the patch-pyramid SWD loss.
const SWD_SLICES: usize = 128;

/// Pyramid levels for `size`-pixel images: as many as keep the coarsest level at least one
/// patch wide, at most [`SWD_LEVELS`].
fn swd_levels(size: usize, patch: usize) -> usize {
    let mut levels = 1;
    while levels < SWD_LEVELS && (size >> levels) >= patch {
        levels += 1;
    }
    levels
}

/// The feature extractor the configuration chose.
pub(super) enum SwdExtractor {
    Patches(PatchPyramid),
    Vgg19(Vgg19),
}

impl FeatureExtractor for SwdExtractor {
    fn layer_count(&self) -> usize {
        match self {
            Self::Patches(pyramid) => pyramid.layer_count(),
            Self::Vgg19(vgg) => vgg.layer_count(),
        }
    }

    fn extract(&self, images: &Tensor) -> swd_loss::Result<Vec<FeatureMap>> {
        match self {
            Self::Patches(pyramid) => pyramid.extract(images),
            Self::Vgg19(vgg) => vgg.extract(images),
        }
    }
}

/// Loads the VGG-19 weights the configuration needs (Heitz et al.'s layers `relu1_1` ..
/// `relu4_4`), or `None` when its SWD loss uses no VGG. Called before training starts, so a
/// missing or broken weights file fails at once, naming the file; a file given to a run that
/// does not use it is refused too, rather than silently ignored.
pub(super) fn load_vgg19(
    config: &TrainConfig,
    weights: Option<&Path>,
    device: &Device,
) -> Result<Option<Vgg19>> {
    let wanted = config.ablations.use_swd && config.losses.swd_features == SwdFeatures::Vgg19;
    match (wanted, weights) {
        (false, None) => Ok(None),
        (false, Some(path)) => Err(invalid(
            "vgg19_weights",
            format!(
                "{} was given, but the configuration's SWD loss does not use VGG-19 features \
                 (use_swd = {}, swd_features = {:?})",
                path.display(),
                config.ablations.use_swd,
                config.losses.swd_features
            ),
        )),
        (true, None) => Err(invalid(
            "vgg19_weights",
            "the configuration's SWD loss compares VGG-19 features (swd_features = vgg19); \
             give the weights file (torchvision's names, see docs/swd-loss.md)",
        )),
        (true, Some(path)) => Vgg19::from_safetensors(path, Vgg19Config::heitz(), device)
            .map(Some)
            .map_err(|e| Error::Weights {
                path: path.to_path_buf(),
                why: match e {
                    // swd-loss's I/O error repeats the path; keep only its cause.
                    swd_loss::Error::Io { source, .. } => source.to_string(),
                    other => format!("not usable as VGG-19 features (torchvision names): {other}"),
                },
            }),
    }
}

/// The texture loss of the configuration against the real views `images` `(V, 3, H, W)` (the
/// final images), or `None` without the SWD loss; `vgg` is what [`load_vgg19`] returned for it.
/// The patch pyramid compares [`SWD_POINTS`] random patches per level along [`SWD_SLICES`]
/// directions; VGG-19 every position along one direction per channel, as Heitz et al.
pub(super) fn texture_loss(
    config: &TrainConfig,
    vgg: Option<&Vgg19>,
    images: &Tensor,
) -> Result<Option<ViewTexture>> {
    if !config.ablations.use_swd {
        return Ok(None);
    }
    let (extractor, loss_config) = match config.losses.swd_features {
        SwdFeatures::Vgg19 => {
            let vgg =
                vgg.ok_or_else(|| invalid("vgg19_weights", "VGG-19 weights are not loaded"))?;
            (
                SwdExtractor::Vgg19(vgg.clone()),
                TextureLossConfig::default().with_slices(Slices::MatchDim),
            )
        }
        SwdFeatures::PatchPyramid => {
            let defaults = PatchPyramidConfig::default();
            let levels = swd_levels(config.final_image_size(), defaults.patch);
            let pyramid = PatchPyramid::new(defaults.with_levels(levels))?;
            (
                SwdExtractor::Patches(pyramid),
                TextureLossConfig::default()
                    .with_slices(Slices::Fixed(SWD_SLICES))
                    .with_points(Points::Random(SWD_POINTS)),
            )
        }
    };
    let loss = TextureLoss::new(extractor, loss_config)?;
    Ok(Some(ViewTexture::new(loss, images)?))
}

/// The texture loss with its real side: the target features of the dataset's views.
///
/// The patch pyramid's levels of every view are extracted once, when training starts (a third
/// more than the images themselves), and each step picks its views' from them: before, every
/// step rebuilt the Laplacian pyramids of the real views it compared. VGG-19's activations are
/// still extracted per step from the compared views only: those of 100 views at 320^2 would
/// take gigabytes.
pub(super) struct ViewTexture {
    loss: TextureLoss<SwdExtractor>,
    /// The real views `(V, 3, H, W)`.
    images: Tensor,
    /// The target of every view, when it is kept.
    every_view: Option<TextureTarget>,
}

impl ViewTexture {
    fn new(loss: TextureLoss<SwdExtractor>, images: &Tensor) -> Result<Self> {
        let every_view = match loss.extractor() {
            SwdExtractor::Patches(_) => Some(loss.target(images)?),
            SwdExtractor::Vgg19(_) => None,
        };
        Ok(Self {
            loss,
            images: images.clone(),
            every_view,
        })
    }

    /// The loss of `generated` `(B, 3, H, W)` against the real views `views`, one per
    /// generated image, along directions (and patches) drawn from `rng`: the same value as
    /// against a target made of those views.
    pub(super) fn loss(
        &self,
        generated: &Tensor,
        views: &[usize],
        rng: &mut impl Rng,
    ) -> Result<Tensor> {
        let target = match &self.every_view {
            Some(every) => every.select(views)?,
            None => self.loss.target(&select(&self.images, views)?)?,
        };
        Ok(self.loss.loss(generated, &target, rng)?)
    }
}

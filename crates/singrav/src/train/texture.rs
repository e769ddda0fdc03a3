//! The last scale's sliced Wasserstein texture loss and the features it compares: the
//! weights-free patch pyramid, or VGG-19 (the paper's choice) when the user supplies weights.

use std::path::Path;

use candle_core::{Device, Tensor};
use swd_loss::{
    FeatureExtractor, FeatureMap, PatchPyramid, PatchPyramidConfig, Slices, TextureLoss,
    TextureLossConfig, Vgg19, Vgg19Config,
};

use crate::config::{SwdFeatures, TrainConfig};
use crate::error::{invalid, Error, Result};

/// The most levels of the weights-free patch pyramid the SWD loss compares.
const SWD_LEVELS: usize = 3;

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
                 (ablations.use_swd = {}, losses.swd_features = {:?})",
                path.display(),
                config.ablations.use_swd,
                config.losses.swd_features
            ),
        )),
        (true, None) => Err(invalid(
            "vgg19_weights",
            "the configuration's SWD loss compares VGG-19 features (losses.swd_features = vgg19); \
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

/// The texture loss of the configuration (on its final images), or `None` without the SWD
/// loss; `vgg` is what [`load_vgg19`] returned for it. The patch pyramid slices each level
/// along swd-loss's default 64 directions, VGG-19 along one per channel, as Heitz et al.
pub(super) fn texture_loss(
    config: &TrainConfig,
    vgg: Option<&Vgg19>,
) -> Result<Option<TextureLoss<SwdExtractor>>> {
    if !config.ablations.use_swd {
        return Ok(None);
    }
    let (extractor, slices) = match config.losses.swd_features {
        SwdFeatures::Vgg19 => {
            let vgg =
                vgg.ok_or_else(|| invalid("vgg19_weights", "VGG-19 weights are not loaded"))?;
            (SwdExtractor::Vgg19(vgg.clone()), Slices::MatchDim)
        }
        SwdFeatures::PatchPyramid => {
            let defaults = PatchPyramidConfig::default();
            let levels = swd_levels(config.final_image_size(), defaults.patch);
            let pyramid = PatchPyramid::new(defaults.with_levels(levels))?;
            (
                SwdExtractor::Patches(pyramid),
                TextureLossConfig::default().slices,
            )
        }
    };
    let loss_config = TextureLossConfig::default().with_slices(slices);
    Ok(Some(TextureLoss::new(extractor, loss_config)?))
}

//! Multi-view metrics of generated scenes, as the paper evaluates SinGRAV: render every generated
//! scene from cameras of the training data, then compare each rendering with the real view from
//! the same camera (see `docs/metrics.md` for what the numbers mean).
//!
//! - [`diversity_mv`]: per view, the spread of the generated scenes relative to the contrast of
//!   the real view; averaged over views. Needs no weights.
//! - [`sifid_mv`]: SinGAN's SIFID ([`sifid`]) between each generated view and the real one,
//!   averaged over views and scenes. Needs InceptionV3's first block
//!   ([`InceptionBlock1::from_safetensors`], weights converted from torchvision).
//! - [`psnr_per_view`] / [`mean_psnr`], [`ssim_per_view`] / [`mean_ssim`], [`depth_rmse`]: how
//!   closely renderings (of the reconstruction, say) reproduce the real views.
//! - [`patch_swd_mv`]: a weights-free analogue of SIFID-MV (sliced Wasserstein distance between
//!   7 x 7 patch distributions of a Laplacian pyramid).
//! - [`colour_swd`]: colour drift, the sliced Wasserstein distance between RGB distributions.
//! - [`floaters`]: the mean opacity generated scenes put where the real views are empty.
//! - [`layout_distance`]: how far a generated volume's matter is from the scene's, in position
//!   and colour (arrangement, which the image metrics cannot see), and
//!   [`layout_distance_by_position`] in position alone (moved matter, not tinted matter);
//!   [`kind_layout_distance`]:
//!   the same by kind of matter ([`MatterKinds`]), each kind with an equal say;
//!   [`MatterSupport::misplaced`]: the share of a volume's matter standing where the scene has
//!   no matter of its kind nearby (matter out of place, which true variants of a scene avoid).
//! - [`Objects`]: the separate things standing on a volume's ground (face-connected solid
//!   matter above it), counted and sized: neighbouring stones run together count as one.
//! - [`Estimate`]: a metric over scenes with its standard error over scenes (per-scene values
//!   from [`floaters_per_scene`], [`colour_swd_per_scene`], [`patch_swd_per_scene`]; a
//!   jackknife for [`diversity_mv`]).
//! - [`FeatureGaussian`]: the Fréchet distance between Gaussians fitted to feature sets, which
//!   SIFID (and FID) is.

mod colour_swd;
mod depth;
mod diversity;
mod error;
mod estimate;
mod floaters;
mod frechet;
mod inception;
mod layout;
mod matter_kinds;
mod misplaced;
mod objects;
mod patch_swd;
mod psnr;
mod sifid;
mod ssim;
#[cfg(test)]
mod test_slabs;

pub use colour_swd::{colour_swd, colour_swd_per_scene};
pub use depth::depth_rmse;
pub use diversity::diversity_mv;
pub use error::{Error, Result};
pub use estimate::Estimate;
pub use floaters::{floaters, floaters_per_scene};
pub use frechet::FeatureGaussian;
pub use inception::InceptionBlock1;
pub use layout::{
    layout_distance, layout_distance_by_position, LayoutPoints, LayoutWeighting, LAYOUT_DIRECTIONS,
};
pub use matter_kinds::{kind_layout_distance, kind_layout_distances, MatterKinds, MATTER_KINDS};
pub use misplaced::{MatterSupport, MISPLACED_KINDS, MISPLACED_REACH};
pub use objects::{
    Object, ObjectRule, Objects, OBJECT_CLEARANCE, OBJECT_DENSITY, OBJECT_GROUND_WINDOW,
};
pub use patch_swd::{
    patch_swd_mv, patch_swd_per_scene, PATCH_SWD_DIRECTIONS, PATCH_SWD_MIN_SIDE, PATCH_SWD_SEED,
};
pub use psnr::{mean_psnr, psnr_per_view};
pub use sifid::{sifid, sifid_mv};
pub use ssim::{mean_ssim, ssim_per_view};

/// Checks the multi-view metrics' input: at least `min_scenes` scenes, each seen from exactly
/// the real views' cameras at their size (same shape as `real`).
fn check_scenes(
    generated: &[candle_core::Tensor],
    real: &candle_core::Tensor,
    min_scenes: usize,
) -> crate::error::Result<()> {
    if generated.len() < min_scenes {
        return Err(crate::error::invalid(
            "generated",
            format!(
                "need at least {min_scenes} scene(s), got {}",
                generated.len()
            ),
        ));
    }
    if let Some(bad) = generated.iter().find(|g| g.shape() != real.shape()) {
        return Err(crate::error::invalid(
            "generated",
            format!(
                "scene views {:?} differ from the real views {:?}",
                bad.dims(),
                real.dims()
            ),
        ));
    }
    Ok(())
}

/// The arithmetic mean of per-scene values (NaN for none; callers check their scenes first).
fn mean(values: &[f64]) -> f64 {
    values.iter().sum::<f64>() / values.len() as f64
}

/// The types most users of this crate need, for `use scene_metrics::prelude::*;`.
pub mod prelude {
    pub use crate::{
        colour_swd, diversity_mv, floaters, mean_psnr, mean_ssim, patch_swd_mv, sifid_mv, Estimate,
        InceptionBlock1,
    };
}

/// The README's examples, compiled and run as doc tests.
#[cfg(doctest)]
#[doc = include_str!("../README.md")]
pub struct ReadmeDoctests;

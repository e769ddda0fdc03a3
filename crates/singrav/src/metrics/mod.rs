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
//! - [`FeatureGaussian`]: the Fréchet distance between Gaussians fitted to feature sets, which
//!   SIFID (and FID) is.

mod colour_swd;
mod depth;
mod diversity;
mod floaters;
mod frechet;
mod inception;
mod patch_swd;
mod psnr;
mod sifid;
mod ssim;

pub use colour_swd::colour_swd;
pub use depth::depth_rmse;
pub use diversity::diversity_mv;
pub use floaters::floaters;
pub use frechet::FeatureGaussian;
pub use inception::InceptionBlock1;
pub use patch_swd::{patch_swd_mv, PATCH_SWD_DIRECTIONS, PATCH_SWD_MIN_SIDE, PATCH_SWD_SEED};
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

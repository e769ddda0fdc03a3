//! Patch-SWD-MV: a weights-free analogue of SIFID-MV, comparing the distributions of small
//! patches of generated and real views.

use candle_core::Tensor;
use rand::SeedableRng;
use swd_loss::{Metric, PatchPyramid, PatchPyramidConfig, Slices, TextureLoss, TextureLossConfig};

use crate::error::Result;

/// Random directions per pyramid level.
pub const PATCH_SWD_DIRECTIONS: usize = 128;
/// Seed of the directions: fixed, so every evaluation slices along the same directions.
pub const PATCH_SWD_SEED: u64 = 0x5eed;
/// The smallest view side [`patch_swd_mv`] accepts: its third pyramid level (a quarter of the
/// side, rounded up twice) must hold a 7 x 7 patch.
pub const PATCH_SWD_MIN_SIDE: usize = 25;

/// For view v of each generated scene and real view v: the sliced Wasserstein distance between
/// the distributions of their 7 x 7 RGB patches at three levels of a Laplacian pyramid (swd-loss's
/// [`PatchPyramid`] defaults: two band-pass levels and the half-resolution-twice Gaussian
/// residual), averaged over views and scenes. Lower is closer; identical views give 0.
///
/// Like SIFID it compares patch statistics, not their layout (a shuffled arrangement of the
/// same stones scores well; blur, noise or wrong colours score badly), but it needs no network
/// weights. Per pair of views the value is `sqrt(mean over levels and directions of W2^2)`, in
/// colour units like [`colour_swd`](super::colour_swd); the directions are
/// [`PATCH_SWD_DIRECTIONS`] per level, unit vectors drawn from a ChaCha8 generator seeded with
/// [`PATCH_SWD_SEED`], the same at every call. `generated` holds one `(V, 3, H, W)` tensor per
/// scene from the cameras of `real` `(V, 3, H, W)`; views need sides of at least
/// [`PATCH_SWD_MIN_SIDE`] pixels.
///
/// ```
/// use candle_core::{Device, Tensor};
/// let real = Tensor::rand(0f32, 1., (2, 3, 28, 28), &Device::Cpu)?;
/// assert_eq!(scene_metrics::patch_swd_mv(&[real.clone()], &real)?, 0.0);
/// let noisy = (&real + Tensor::randn(0f32, 0.2, (2, 3, 28, 28), &Device::Cpu)?)?;
/// assert!(scene_metrics::patch_swd_mv(&[noisy], &real)? > 0.01);
/// # Ok::<(), scene_metrics::Error>(())
/// ```
pub fn patch_swd_mv(generated: &[Tensor], real: &Tensor) -> Result<f64> {
    Ok(super::mean(&patch_swd_per_scene(generated, real)?))
}

/// [`patch_swd_mv`] of each scene on its own, averaged over its views (their mean is
/// [`patch_swd_mv`]; the same fixed directions for every scene).
///
/// ```
/// use candle_core::{Device, Tensor};
/// let real = Tensor::rand(0f32, 1.0, (1, 3, 32, 32), &Device::Cpu)?;
/// let per_scene = scene_metrics::patch_swd_per_scene(&[real.clone(), (&real * 0.5)?], &real)?;
/// assert_eq!(per_scene[0], 0.0);
/// assert!(per_scene[1] > 0.0);
/// # Ok::<(), scene_metrics::Error>(())
/// ```
pub fn patch_swd_per_scene(generated: &[Tensor], real: &Tensor) -> Result<Vec<f64>> {
    super::check_scenes(generated, real, 1)?;
    let pyramid = PatchPyramid::new(PatchPyramidConfig::default())?;
    let levels = pyramid.config().levels;
    let loss = TextureLoss::new(
        pyramid,
        TextureLossConfig::default()
            .with_slices(Slices::Fixed(PATCH_SWD_DIRECTIONS))
            .with_metric(Metric::SquaredW2),
    )?
    .with_layer_weights(vec![1.0 / levels as f64; levels])?;
    let views = real.dim(0)?;
    let targets = (0..views)
        .map(|v| loss.target(&real.narrow(0, v, 1)?).map_err(Into::into))
        .collect::<Result<Vec<_>>>()?;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(PATCH_SWD_SEED);
    let directions = loss.draw_projections(&targets[0], &mut rng)?;
    generated
        .iter()
        .map(|scene| {
            let mut total = 0.0;
            for (v, target) in targets.iter().enumerate() {
                let value =
                    loss.loss_with_projections(&scene.narrow(0, v, 1)?, target, &directions)?;
                total += f64::from(
                    value
                        .to_dtype(candle_core::DType::F32)?
                        .to_scalar::<f32>()?,
                )
                .sqrt();
            }
            Ok(total / views as f64)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::{DType, Device};

    /// Smooth random views (coarse noise upsampled), in [0.2, 0.8].
    fn views(seed: u64, n: usize, size: usize) -> Tensor {
        use rand::Rng;
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let coarse = size / 4;
        let values: Vec<f32> = (0..n * 3 * coarse * coarse)
            .map(|_| rng.random_range(0.2..0.8))
            .collect();
        Tensor::from_vec(values, (n, 3, coarse, coarse), &Device::Cpu)
            .unwrap()
            .upsample_nearest2d(size, size)
            .unwrap()
    }

    #[test]
    fn identical_views_give_zero_and_the_value_is_fixed_by_the_seed() {
        let real = views(1, 2, 32);
        assert_eq!(
            patch_swd_mv(&[real.clone(), real.clone()], &real).unwrap(),
            0.0
        );
        let other = views(2, 2, 32);
        let a = patch_swd_mv(std::slice::from_ref(&other), &real).unwrap();
        assert!(a > 0.01, "{a}");
        assert_eq!(a, patch_swd_mv(&[other], &real).unwrap());
    }

    #[test]
    fn a_constant_shift_moves_only_the_coarsest_level_by_about_its_rms() {
        // The band-pass levels do not see a constant shift; the Gaussian residual's 147-D patch
        // points move by s repeated 49 times per channel, whose squared projection onto random
        // unit directions averages |s|^2 * 49 / 147 = |s|^2 / 3. Over three levels the value is
        // about sqrt(|s|^2 / 9); 128 directions leave a Monte Carlo error of about 12 %.
        let real = views(3, 1, 32);
        let shifted = (&real + 0.06).unwrap();
        let got = patch_swd_mv(&[shifted], &real).unwrap();
        let want = (3.0 * 0.06f64 * 0.06 / 9.0).sqrt();
        assert!((got / want - 1.0).abs() < 0.15, "{got} vs {want}");
    }

    #[test]
    fn noise_scores_worse_than_a_translation_of_the_same_texture() {
        // A view moved by 4 pixels (a whole pixel at every level) keeps most of its patches;
        // added noise changes every one, even though it is a smaller pixel error.
        let wide = views(4, 1, 64);
        let real = wide.narrow(3, 0, 56).unwrap();
        let moved = wide.narrow(3, 4, 56).unwrap();
        let noise = Tensor::randn(0f32, 0.1, (1, 3, 64, 56), &Device::Cpu).unwrap();
        let noisy = (&real + noise).unwrap();
        let pixel_error = |x: &Tensor| {
            (x - &real)
                .unwrap()
                .sqr()
                .unwrap()
                .mean_all()
                .unwrap()
                .to_scalar::<f32>()
                .unwrap()
        };
        assert!(pixel_error(&noisy) < pixel_error(&moved));
        let moved = patch_swd_mv(&[moved], &real).unwrap();
        let noisy = patch_swd_mv(&[noisy], &real).unwrap();
        assert!(2.0 * moved < noisy, "moved {moved}, noisy {noisy}");
        let side = PATCH_SWD_MIN_SIDE;
        let smallest = Tensor::zeros((1, 3, side, side), DType::F32, &Device::Cpu).unwrap();
        assert_eq!(
            patch_swd_mv(std::slice::from_ref(&smallest), &smallest).unwrap(),
            0.0
        );
        let small = smallest.narrow(2, 0, side - 1).unwrap();
        assert!(patch_swd_mv(std::slice::from_ref(&small), &small).is_err());
    }
}

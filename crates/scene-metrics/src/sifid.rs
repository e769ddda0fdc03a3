//! SIFID (SinGAN's single-image FID) between two images, and the paper's SIFID-MV over the views
//! of generated scenes.

use candle_core::Tensor;

use super::frechet::FeatureGaussian;
use super::inception::InceptionBlock1;
use crate::error::{invalid, Result};

/// SinGAN's SIFID: the Fréchet distance between Gaussians fitted to the feature vectors of
/// `real` and `fake` under InceptionV3's first block, each spatial position of the 64-channel
/// feature map one sample (as SinGAN's `sifid_score.py` with `dims=64`). Images are RGB in
/// [0, 1], `(3, H, W)` or `(1, 3, H, W)`, fed at their own size; they need not be the same size,
/// but each must give a feature map of at least two positions (sides of at least 11 and 15
/// pixels). Lower is closer; an image against itself gives 0.
///
/// ```no_run
/// use candle_core::{Device, Tensor};
/// use scene_metrics::{sifid, InceptionBlock1};
/// // Weights converted from torchvision, as docs/metrics.md shows.
/// let block = InceptionBlock1::from_safetensors("inception-block1.safetensors", &Device::Cpu)?;
/// let real = Tensor::rand(0f32, 1., (3, 64, 64), &Device::Cpu)?;
/// let darker = (&real * 0.8)?;
/// assert!(sifid(&real, &real, &block)? < 1e-9);
/// println!("SIFID of a darker copy: {:.4}", sifid(&real, &darker, &block)?);
/// # Ok::<(), scene_metrics::Error>(())
/// ```
pub fn sifid(real: &Tensor, fake: &Tensor, block: &InceptionBlock1) -> Result<f64> {
    let one = |image: &Tensor, what: &str| -> Result<FeatureGaussian> {
        let batch = match image.dims() {
            [3, _, _] => image.unsqueeze(0)?,
            [1, 3, _, _] => image.clone(),
            dims => {
                return Err(invalid(
                    what,
                    format!("expected (3, H, W) or (1, 3, H, W), got {dims:?}"),
                ))
            }
        };
        Ok(view_gaussians(&batch, block)?.remove(0))
    };
    one(real, "real")?.frechet_distance(&one(fake, "fake")?)
}

/// The paper's SIFID-MV: [`sifid`] between view v of each generated scene and real view v,
/// averaged over views and scenes. `generated` holds one `(V, 3, H, W)` tensor per scene, all
/// rendered from the cameras of `real` `(V, 3, H, W)`; RGB in [0, 1]. The paper uses 50 scenes
/// and 40 views.
///
/// ```no_run
/// # use candle_core::{Device, Tensor};
/// # let block = scene_metrics::InceptionBlock1::from_safetensors("w.safetensors", &Device::Cpu)?;
/// let real = Tensor::rand(0f32, 1., (4, 3, 64, 64), &Device::Cpu)?;
/// let same = vec![real.clone(), real.clone()];
/// assert!(scene_metrics::sifid_mv(&same, &real, &block)? < 1e-6);
/// # Ok::<(), scene_metrics::Error>(())
/// ```
pub fn sifid_mv(generated: &[Tensor], real: &Tensor, block: &InceptionBlock1) -> Result<f64> {
    super::check_scenes(generated, real, 1)?;
    let real = view_gaussians(real, block)?;
    let mut total = 0.0;
    for scene in generated {
        for (fake, real) in view_gaussians(scene, block)?.iter().zip(&real) {
            total += real.frechet_distance(fake)?;
        }
    }
    Ok(total / (generated.len() * real.len()) as f64)
}

/// Per image of `images` `(B, 3, H, W)`: the Gaussian of its feature map's positions.
fn view_gaussians(images: &Tensor, block: &InceptionBlock1) -> Result<Vec<FeatureGaussian>> {
    let features = block.features(images)?;
    let (batch, channels, h, w) = features.dims4()?;
    if h * w < 2 {
        return Err(invalid(
            "images",
            format!(
                "{:?} give a {h} x {w} feature map; SIFID needs at least 2 positions \
                 (sides of at least 11 and 15 pixels)",
                images.dims()
            ),
        ));
    }
    // (B, 64, h, w) -> (B, h * w, 64): one row per position.
    let samples = features
        .reshape((batch, channels, h * w))?
        .transpose(1, 2)?;
    (0..batch)
        .map(|b| FeatureGaussian::fit(&samples.get(b)?))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::inception::tests::random_block;
    use candle_core::{DType, Device};

    /// Smooth random images (low-frequency noise upsampled), like renderings more than like
    /// white noise, in [0, 1].
    fn images(seed: u64, n: usize, size: usize) -> Tensor {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let coarse = size / 4;
        let values: Vec<f32> = (0..n * 3 * coarse * coarse)
            .map(|_| rng.random_range(0.0..1.0))
            .collect();
        Tensor::from_vec(values, (n, 3, coarse, coarse), &Device::Cpu)
            .unwrap()
            .upsample_nearest2d(size, size)
            .unwrap()
    }

    #[test]
    fn an_image_against_itself_is_zero_in_either_layout() {
        let block = random_block(10);
        let image = images(1, 1, 40);
        let d = sifid(&image, &image, &block).unwrap();
        assert!(d.abs() < 1e-9, "{d}");
        let other = images(2, 1, 40).squeeze(0).unwrap();
        let d3 = sifid(&image.squeeze(0).unwrap(), &other, &block).unwrap();
        let d4 = sifid(&image, &other.unsqueeze(0).unwrap(), &block).unwrap();
        assert!(d3 > 1e-3, "{d3}");
        assert_eq!(d3, d4);
        // Images of different sizes compare too: statistics, not pixels.
        assert!(sifid(&image, &images(3, 1, 48), &block).unwrap() > 0.0);
    }

    #[test]
    fn sifid_mv_is_zero_for_identical_scenes_and_grows_with_a_perturbation() {
        let block = random_block(11);
        let real = images(4, 3, 32);
        let same = vec![real.clone(), real.clone()];
        let zero = sifid_mv(&same, &real, &block).unwrap();
        assert!(zero.abs() < 1e-9, "{zero}");

        let noise = images(5, 3, 32).affine(1.0, -0.5).unwrap();
        let perturbed = |amount: f64| -> Tensor {
            (&real + (&noise * amount).unwrap())
                .unwrap()
                .clamp(0f32, 1f32)
                .unwrap()
        };
        let small = sifid_mv(&[real.clone(), perturbed(0.1)], &real, &block).unwrap();
        let large = sifid_mv(&[real.clone(), perturbed(0.5)], &real, &block).unwrap();
        assert!(small > 1e-4, "{small}");
        assert!(large > 2.0 * small, "{small} then {large}");

        // The average over scenes and views of the per-image SIFID.
        let scenes = [perturbed(0.2), perturbed(0.3)];
        let mut by_view = 0.0;
        for scene in &scenes {
            for v in 0..3 {
                by_view += sifid(&real.get(v).unwrap(), &scene.get(v).unwrap(), &block).unwrap();
            }
        }
        let mv = sifid_mv(&scenes, &real, &block).unwrap();
        assert!(
            (mv - by_view / 6.0).abs() < 1e-9 * mv,
            "{mv} vs {}",
            by_view / 6.0
        );
    }

    #[test]
    fn mismatched_or_too_small_views_are_errors() {
        let block = random_block(12);
        let real = images(6, 2, 32);
        assert!(sifid_mv(&[], &real, &block).is_err());
        let err = sifid_mv(&[images(7, 3, 32)], &real, &block)
            .unwrap_err()
            .to_string();
        assert!(err.contains("[3, 3, 32, 32]"), "{err}");
        // 12 x 12 images give a 1 x 1 feature map: no covariance.
        let tiny = Tensor::rand(0f32, 1., (1, 3, 12, 12), &Device::Cpu).unwrap();
        let err = sifid(&tiny, &tiny, &block).unwrap_err().to_string();
        assert!(err.contains("1 x 1"), "{err}");
        let batch = Tensor::zeros((2, 3, 32, 32), DType::F32, &Device::Cpu).unwrap();
        assert!(sifid(&batch, &batch, &block).is_err());
    }
}

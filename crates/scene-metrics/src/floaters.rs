//! Floaters: matter that generated scenes put where the real scene has none.

use candle_core::{DType, Tensor};

use crate::error::{invalid, Result};

/// The mean rendered opacity of generated scenes over the pixels where the real view's alpha is
/// 0 (empty sky in every real view): 0 when the generated scenes leave the sky empty, 1 when it
/// is opaque. `generated` holds one `(V, 1, H, W)` opacity tensor per scene, rendered from the
/// cameras of `real_alpha` `(V, 1, H, W)`. The mean is over those pixels of every view and
/// scene. `None` when no real pixel has alpha exactly 0 (nothing to measure).
///
/// ```
/// use candle_core::{Device, Tensor};
/// // One view of 4 pixels; the real scene covers the first two.
/// let real = Tensor::new(&[[[[1.0f32, 0.5], [0.0, 0.0]]]], &Device::Cpu)?;
/// // A blob of opacity 0.6 over the whole view.
/// let blob = Tensor::full(0.6f32, (1, 1, 2, 2), &Device::Cpu)?;
/// let f = scene_metrics::floaters(&[blob], &real)?.unwrap();
/// assert!((f - 0.6).abs() < 1e-7);
/// # Ok::<(), scene_metrics::Error>(())
/// ```
pub fn floaters(generated: &[Tensor], real_alpha: &Tensor) -> Result<Option<f64>> {
    Ok(floaters_per_scene(generated, real_alpha)?.map(|per_scene| super::mean(&per_scene)))
}

/// [`floaters`] of each scene on its own (their mean is [`floaters`]): what
/// [`Estimate::mean_of`](super::Estimate::mean_of) turns into a standard error over scenes.
/// `None` when no real pixel has alpha exactly 0.
///
/// ```
/// use candle_core::{Device, Tensor};
/// let real = Tensor::new(&[[[[1.0f32, 0.0]]]], &Device::Cpu)?;
/// let clear = real.clone();
/// let hazy = Tensor::new(&[[[[1.0f32, 0.4]]]], &Device::Cpu)?;
/// let per_scene = scene_metrics::floaters_per_scene(&[clear, hazy], &real)?.unwrap();
/// assert_eq!(per_scene, vec![0.0, 0.4f32 as f64]);
/// # Ok::<(), scene_metrics::Error>(())
/// ```
pub fn floaters_per_scene(generated: &[Tensor], real_alpha: &Tensor) -> Result<Option<Vec<f64>>> {
    super::check_scenes(generated, real_alpha, 1)?;
    let sky = real_alpha.eq(0f64)?.to_dtype(DType::F64)?;
    let sky_pixels = sky.sum_all()?.to_scalar::<f64>()?;
    if sky_pixels == 0.0 {
        return Ok(None);
    }
    let per_scene = generated
        .iter()
        .enumerate()
        .map(|(s, scene)| {
            let opacity = scene.to_dtype(DType::F64)?;
            let (min, max) = (
                opacity.min_all()?.to_scalar::<f64>()?,
                opacity.max_all()?.to_scalar::<f64>()?,
            );
            if min < 0.0 || max > 1.0 + 1e-6 {
                return Err(invalid(
                    "generated opacity",
                    format!("scene {s} has opacity in [{min}, {max}], expected values in [0, 1]"),
                ));
            }
            Ok((opacity * &sky)?.sum_all()?.to_scalar::<f64>()? / sky_pixels)
        })
        .collect::<Result<Vec<_>>>()?;
    Ok(Some(per_scene))
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::Device;

    /// A real view whose left half is the scene (alpha 1) and whose right half is sky.
    fn half_covered() -> Tensor {
        let row: Vec<f32> = (0..8).map(|x| if x < 4 { 1.0 } else { 0.0 }).collect();
        let plane: Vec<f32> = (0..6).flat_map(|_| row.clone()).collect();
        Tensor::from_vec([plane.clone(), plane].concat(), (2, 1, 6, 8), &Device::Cpu).unwrap()
    }

    #[test]
    fn an_opaque_blob_in_the_sky_gives_its_opacity() {
        let real = half_covered();
        // Scene 1: the real scene (left half) and nothing in the sky.
        let clean = real.clone();
        assert_eq!(
            floaters(std::slice::from_ref(&clean), &real).unwrap(),
            Some(0.0)
        );
        // Scene 2: a 2 x 2 blob of opacity 0.8 in the sky of view 0, and the scene itself.
        let mut values: Vec<f32> = real.flatten_all().unwrap().to_vec1().unwrap();
        for (y, x) in [(1, 5), (1, 6), (2, 5), (2, 6)] {
            values[y * 8 + x] = 0.8;
        }
        let blob = Tensor::from_vec(values, (2, 1, 6, 8), &Device::Cpu).unwrap();
        // 4 of the 2 x 24 sky pixels at 0.8.
        let want = 4.0 * 0.8 / 48.0;
        let got = floaters(std::slice::from_ref(&blob), &real)
            .unwrap()
            .unwrap();
        assert!((got - want).abs() < 1e-7, "{got} vs {want}");
        // Over both scenes: the mean.
        let both = floaters(&[clean, blob], &real).unwrap().unwrap();
        assert!((both - want / 2.0).abs() < 1e-7, "{both}");
        // A blob covering the whole sky gives exactly its opacity.
        let fog = Tensor::full(0.35f32, (2, 1, 6, 8), &Device::Cpu).unwrap();
        let got = floaters(&[fog], &real).unwrap().unwrap();
        assert!((got - 0.35).abs() < 1e-7, "{got}");
    }

    #[test]
    fn no_sky_is_none_and_bad_opacity_is_an_error() {
        let full = Tensor::ones((1, 1, 4, 4), DType::F32, &Device::Cpu).unwrap();
        assert_eq!(floaters(std::slice::from_ref(&full), &full).unwrap(), None);
        let real = half_covered();
        let bad = (Tensor::ones((2, 1, 6, 8), DType::F32, &Device::Cpu).unwrap() * 2.0).unwrap();
        let err = floaters(&[bad], &real).unwrap_err().to_string();
        assert!(err.contains("[0, 1]"), "{err}");
    }
}

//! Colour drift: the sliced Wasserstein distance between the RGB distributions of generated and
//! real views.

use candle_core::{DType, Device, Tensor};
use swd_loss::{sliced_wasserstein_per_projection, Metric, Projections};

use crate::error::Result;

/// How far the colours of generated views are from the real views' colours, ignoring where the
/// colours are: for view v of each scene, the pixels' RGB values and real view v's are two
/// point sets in colour space, compared by the sliced Wasserstein distance; averaged over views
/// and scenes. `generated` holds one `(V, 3, H, W)` tensor per scene, seen from the cameras of
/// `real` `(V, 3, H, W)`.
///
/// Per pair of views the value is `sqrt(mean_k W2^2_k)`, the root mean over directions of the
/// squared 1D Wasserstein-2 distances, along the 13 symmetry axes of the RGB cube (3 channel
/// axes, 4 diagonals including grey, 6 face diagonals), computed in f64. Those axes average any
/// `(s . theta)^2` to `|s|^2 / 3`, so a constant colour shift `s` gives exactly the root mean
/// square of its channels, `sqrt((s_r^2 + s_g^2 + s_b^2) / 3)`: read the value as a colour
/// error in [0, 1] units. Identical colour distributions give 0.
///
/// ```
/// use candle_core::{Device, Tensor};
/// let real = Tensor::rand(0.2f32, 0.8, (2, 3, 8, 8), &Device::Cpu)?;
/// // Every pixel 0.1 redder and 0.1 less blue: sqrt((0.01 + 0 + 0.01) / 3).
/// let shift = Tensor::new(&[0.1f32, 0.0, -0.1], &Device::Cpu)?.reshape((1, 3, 1, 1))?;
/// let tinted = real.broadcast_add(&shift)?;
/// let d = scene_metrics::colour_swd(&[tinted], &real)?;
/// assert!((d - (0.02f64 / 3.0).sqrt()).abs() < 1e-6);
/// assert_eq!(scene_metrics::colour_swd(&[real.clone()], &real)?, 0.0);
/// # Ok::<(), scene_metrics::Error>(())
/// ```
pub fn colour_swd(generated: &[Tensor], real: &Tensor) -> Result<f64> {
    Ok(super::mean(&colour_swd_per_scene(generated, real)?))
}

/// [`colour_swd`] of each scene on its own, averaged over its views (their mean is
/// [`colour_swd`]).
///
/// ```
/// use candle_core::{Device, Tensor};
/// let real = Tensor::full(0.5f32, (1, 3, 2, 2), &Device::Cpu)?;
/// let grey = real.clone();
/// let brighter = (&real + 0.1)?;
/// let per_scene = scene_metrics::colour_swd_per_scene(&[grey, brighter], &real)?;
/// assert!(per_scene[0] < 1e-12 && (per_scene[1] - 0.1).abs() < 1e-6);
/// # Ok::<(), scene_metrics::Error>(())
/// ```
pub fn colour_swd_per_scene(generated: &[Tensor], real: &Tensor) -> Result<Vec<f64>> {
    super::check_scenes(generated, real, 1)?;
    let axes = cube_axes(real.device())?;
    let views = real.dim(0)?;
    let pixels = |images: &Tensor, v: usize| -> Result<Tensor> {
        Ok(images
            .get(v)?
            .to_dtype(DType::F64)?
            .flatten_from(1)?
            .t()?
            .contiguous()?)
    };
    let real_pixels: Vec<Tensor> = (0..views).map(|v| pixels(real, v)).collect::<Result<_>>()?;
    generated
        .iter()
        .map(|scene| {
            let mut total = 0.0;
            for (v, real_v) in real_pixels.iter().enumerate() {
                let per_axis = sliced_wasserstein_per_projection(
                    &pixels(scene, v)?,
                    real_v,
                    &axes,
                    Metric::SquaredW2,
                )?;
                total += per_axis.mean_all()?.to_scalar::<f64>()?.sqrt();
            }
            Ok(total / views as f64)
        })
        .collect()
}

/// The 13 symmetry axes of the cube as unit columns of a `(3, 13)` matrix: a spherical
/// 2-design (each group of axes averages `(s . theta)^2` to `|s|^2 / 3` on its own).
fn cube_axes(device: &Device) -> Result<Projections> {
    let (h, d) = (0.5f64.sqrt(), (1.0f64 / 3.0).sqrt());
    let axes: [[f64; 3]; 13] = [
        [1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [0.0, 0.0, 1.0],
        [d, d, d],
        [d, d, -d],
        [d, -d, d],
        [-d, d, d],
        [h, h, 0.0],
        [h, -h, 0.0],
        [h, 0.0, h],
        [h, 0.0, -h],
        [0.0, h, h],
        [0.0, h, -h],
    ];
    let columns: Vec<f64> = (0..3)
        .flat_map(|c| axes.iter().map(move |a| a[c]))
        .collect();
    Ok(Projections::from_tensor(Tensor::from_vec(
        columns,
        (3, axes.len()),
        device,
    )?)?)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_axes_are_unit_and_average_any_square_projection_to_a_third() {
        let axes = cube_axes(&Device::Cpu).unwrap();
        let m: Vec<Vec<f64>> = axes.as_tensor().t().unwrap().to_vec2().unwrap();
        for a in &m {
            assert!((a.iter().map(|x| x * x).sum::<f64>() - 1.0).abs() < 1e-15);
        }
        let s = [0.3, -0.7, 0.2];
        let mean: f64 = m
            .iter()
            .map(|a| (a[0] * s[0] + a[1] * s[1] + a[2] * s[2]).powi(2))
            .sum::<f64>()
            / 13.0;
        assert!((mean - (0.09 + 0.49 + 0.04) / 3.0).abs() < 1e-15);
    }

    #[test]
    fn a_shift_gives_its_rms_a_permutation_nothing_and_scenes_average() {
        let dev = Device::Cpu;
        let real = Tensor::rand(0.2f32, 0.8, (3, 3, 10, 12), &dev).unwrap();
        // The same pixels in another arrangement (the image flipped) have the same colours.
        let flipped = Tensor::cat(
            &(0..10)
                .rev()
                .map(|r| real.narrow(2, r, 1).unwrap())
                .collect::<Vec<_>>(),
            2,
        )
        .unwrap();
        assert!(colour_swd(&[flipped], &real).unwrap() < 1e-12);
        let shifted = |s: [f32; 3]| {
            let s = Tensor::new(&s, &dev)
                .unwrap()
                .reshape((1, 3, 1, 1))
                .unwrap();
            real.broadcast_add(&s).unwrap()
        };
        let a = colour_swd(&[shifted([0.05, 0.05, 0.05])], &real).unwrap();
        assert!((a - 0.05).abs() < 1e-6, "{a}");
        let b = colour_swd(&[shifted([0.0, -0.2, 0.1])], &real).unwrap();
        assert!((b - (0.05f64 / 3.0).sqrt()).abs() < 1e-6, "{b}");
        let both = colour_swd(
            &[shifted([0.05, 0.05, 0.05]), shifted([0.0, -0.2, 0.1])],
            &real,
        )
        .unwrap();
        assert!((both - (a + b) / 2.0).abs() < 1e-12);
        assert!(colour_swd(&[], &real).is_err());
    }
}

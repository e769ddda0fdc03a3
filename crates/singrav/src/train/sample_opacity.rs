//! Priors on the rendered opacity of generated scenes.
//!
//! The real views are almost binary (sky 0, matter 1, a thin edge between), while samples of
//! the stones scene showed smudges of partial opacity beside and above the stones: most of what
//! the floaters metric counts (docs/training.md, "Floaters"). Neither term below cares where
//! matter is, so samples may still vary the layout.
//!
//! - [`opacity_binary_loss`]: `4 a (1 - a)` per pixel, 0 where a pixel is clear or opaque and 1
//!   where it is half-transparent, a quadratic form of the beta prior on opacity of Neural
//!   Volumes (Lombardi et al. 2019), which has the same aim.
//! - [`opacity_distribution_loss`]: the exact 1D Wasserstein-2 distance between a sample's pixel
//!   opacities and the real view's alpha from the same camera: haze costs its distance to the
//!   clear or opaque pixels the real view has in its place, and the share of opaque pixels is
//!   kept near the real view's.

use candle_core::{Device, Tensor};
use swd_loss::Projections;

use super::colour::pixel_distribution_distance;
use crate::error::Result;

/// The mean over pixels of `4 a (1 - a)` of the `generated` opacity `a` (`(V, 1, h, w)`).
pub(super) fn opacity_binary_loss(generated: &Tensor) -> Result<Tensor> {
    Ok(((generated * (1.0 - generated)?)? * 4.0)?.mean_all()?)
}

/// The mean over views of the squared W2 distance between the pixel opacities of `generated`
/// and the `real` alpha (both `(V, 1, h, w)`).
pub(super) fn opacity_distribution_loss(generated: &Tensor, real: &Tensor) -> Result<Tensor> {
    // One direction in a one-dimensional space: the sliced distance is the exact 1D one.
    let identity = Projections::from_tensor(Tensor::new(&[[1.0f64]], &Device::Cpu)?)?;
    pixel_distribution_distance(generated, real, || Ok(identity.clone()))
}

#[cfg(test)]
mod tests {
    use candle_core::{Device, Tensor, Var};

    use super::{opacity_binary_loss, opacity_distribution_loss};

    /// `views` views of 2 x 2 pixels from per-pixel values, view-major.
    fn views(values: &[f32]) -> Tensor {
        Tensor::from_vec(values.to_vec(), (values.len() / 4, 1, 2, 2), &Device::Cpu).unwrap()
    }

    fn scalar(t: &Tensor) -> f32 {
        t.to_scalar::<f32>().unwrap()
    }

    #[test]
    fn binary_prior_is_zero_on_clear_and_opaque_pixels_and_its_gradient_is_hand_derived() {
        assert_eq!(
            scalar(&opacity_binary_loss(&views(&[0., 1., 1., 0.])).unwrap()),
            0.0
        );
        // 4 a (1 - a) at 0, 0.25, 0.5, 1: 0, 0.75, 1, 0; mean 0.4375.
        let opacity = Var::from_tensor(&views(&[0., 0.25, 0.5, 1.])).unwrap();
        let loss = opacity_binary_loss(opacity.as_tensor()).unwrap();
        assert!((scalar(&loss) - 0.4375).abs() < 1e-7);
        // d/da of mean(4 a (1 - a)) over 4 pixels: (4 - 8 a) / 4.
        let grads = loss.backward().unwrap();
        let grad: Vec<f32> = grads
            .get(opacity.as_tensor())
            .unwrap()
            .flatten_all()
            .unwrap()
            .to_vec1()
            .unwrap();
        for (g, a) in grad.iter().zip([0f32, 0.25, 0.5, 1.]) {
            assert!((g - (4.0 - 8.0 * a) / 4.0).abs() < 1e-6, "{grad:?}");
        }
    }

    #[test]
    fn distribution_ignores_the_layout_and_prices_haze_by_its_distance_to_the_real_opacities() {
        let real = views(&[1., 1., 0., 0., 0., 1., 0., 0.]);
        // The same opacities elsewhere in each view: a new layout costs nothing.
        let moved = views(&[0., 0., 1., 1., 0., 0., 1., 0.]);
        assert!(scalar(&opacity_distribution_loss(&moved, &real).unwrap()).abs() < 1e-7);
        // View 1: two half-opaque pixels where the real view has two opaque ones (sorted pairs
        // (0, 0), (0, 0), (0.5, 1), (0.5, 1)): W2^2 = 2 * 0.25 / 4. View 2: haze of 0.2 over
        // the clear pixels (sorted pairs (0.2, 0) x 3, (1, 1)): 3 * 0.04 / 4. Mean over views.
        let hazy = views(&[0.5, 0.5, 0., 0., 0.2, 1., 0.2, 0.2]);
        let loss = scalar(&opacity_distribution_loss(&hazy, &real).unwrap());
        let expected = (2.0 * 0.25 / 4.0 + 3.0 * 0.04 / 4.0) / 2.0;
        assert!((loss - expected).abs() < 1e-6, "{loss} against {expected}");
    }
}

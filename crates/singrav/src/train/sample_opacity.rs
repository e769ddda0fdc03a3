//! Priors on the rendered opacity of generated scenes.
//!
//! The real views are almost binary (sky 0, matter 1, a thin edge between), while samples of
//! the stones scene showed smudges of partial opacity beside and above the stones: most of what
//! the floaters metric counts (docs/journal/2026-11-training-quality.md, "Floaters"). The term below does not care where
//! matter is, so samples may still vary the layout.
//!
//! [`opacity_binary_loss`]: `4 a (1 - a)` per pixel, 0 where a pixel is clear or opaque and 1
//! where it is half-transparent, a quadratic form of the beta prior on opacity of Neural
//! Volumes (Lombardi et al. 2019), which has the same aim.

use candle_core::Tensor;

use crate::error::Result;

/// The mean over pixels of `4 a (1 - a)` of the `generated` opacity `a` (`(V, 1, h, w)`).
pub(super) fn opacity_binary_loss(generated: &Tensor) -> Result<Tensor> {
    Ok(((generated * (1.0 - generated)?)? * 4.0)?.mean_all()?)
}

#[cfg(test)]
mod tests {
    use candle_core::{Device, Tensor, Var};

    use super::opacity_binary_loss;

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
}

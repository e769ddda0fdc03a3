//! The colour-distribution loss of generated scenes: a sample rendered from a camera
//! should show the colours the real view from that camera shows, in the same proportions.
//!
//! The critics judge colour only through their small receptive fields and learn it slowly;
//! samples of the stones scene kept blue and purple stones on grey-stone views. This term
//! compares the two views' pixel colours as point sets in RGB, by the sliced Wasserstein
//! distance (squared W2 along random directions), which is indifferent to where the colours
//! are, so it constrains colours, not the layout a sample may vary.

use candle_core::Tensor;
use swd_loss::{sliced_wasserstein, Metric, Projections};

use crate::error::Result;

/// Random directions in RGB per view and step.
const DIRECTIONS: usize = 16;

/// The mean over views of the squared sliced W2 distance between the pixel colours of
/// `generated` and `real` (both `(V, 3, h, w)`), along directions drawn from `rng`.
pub(super) fn colour_distribution_loss(
    generated: &Tensor,
    real: &Tensor,
    rng: &mut impl rand::Rng,
) -> Result<Tensor> {
    pixel_distribution_distance(generated, real, || {
        Ok(Projections::random(3, DIRECTIONS, rng, generated.device())?)
    })
}

/// The mean over views of the squared sliced W2 distance between the pixels of `generated`
/// and `real` (both `(V, C, h, w)`) as point sets in C dimensions, along the directions
/// `directions` gives for each view in turn.
pub(super) fn pixel_distribution_distance(
    generated: &Tensor,
    real: &Tensor,
    mut directions: impl FnMut() -> Result<Projections>,
) -> Result<Tensor> {
    let views = generated.dim(0)?;
    let pixels = |images: &Tensor, v: usize| -> Result<Tensor> {
        // (C, h, w) -> (h w, C): one point per pixel.
        Ok(images.get(v)?.flatten_from(1)?.t()?.contiguous()?)
    };
    let mut per_view = Vec::with_capacity(views);
    for v in 0..views {
        per_view.push(sliced_wasserstein(
            &pixels(generated, v)?,
            &pixels(real, v)?,
            &directions()?,
            Metric::SquaredW2,
        )?);
    }
    Ok(Tensor::stack(&per_view, 0)?.mean(0)?)
}

#[cfg(test)]
mod tests {
    use candle_core::{Device, Tensor};
    use rand::SeedableRng;

    use super::colour_distribution_loss;

    #[test]
    fn a_constant_shift_costs_its_squared_length_projected_and_a_permutation_nothing() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
        let real = Tensor::rand(0f32, 1f32, (2, 3, 4, 5), &Device::Cpu).unwrap();
        // The same pixels in another order: the same colours, another layout.
        let flipped = real.flip(&[2, 3]).unwrap();
        let same = colour_distribution_loss(&flipped, &real, &mut rng).unwrap();
        assert!(same.to_scalar::<f32>().unwrap().abs() < 1e-10);
        // A constant shift s moves every pixel's projection on u by s . u, so each direction
        // costs (s . u)^2: the loss is their mean over the directions drawn.
        let shift = 0.1f32;
        let tinted = (&real + f64::from(shift)).unwrap();
        let mut seeded = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let loss = colour_distribution_loss(&tinted, &real, &mut seeded)
            .unwrap()
            .to_scalar::<f32>()
            .unwrap();
        let mut again = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let mut expected = 0.0f64;
        for _ in 0..2 {
            let p = swd_loss::Projections::random(3, super::DIRECTIONS, &mut again, &Device::Cpu)
                .unwrap();
            // Column k of the (3, K) matrix is direction u_k; s . u_k = shift * sum_c u_k[c].
            let component_sums: Vec<f64> = p.as_tensor().sum(0).unwrap().to_vec1().unwrap();
            for sum in component_sums {
                let along = sum * f64::from(shift);
                expected += along * along;
            }
        }
        expected /= 2.0 * super::DIRECTIONS as f64;
        assert!(
            (f64::from(loss) - expected).abs() < 1e-5,
            "{loss} against {expected}"
        );
    }
}

//! The height profile of generated scenes: how much matter a sample shows at each height of a
//! view, against the real view from the same camera.
//!
//! The critics judge a sample through small receptive fields, so a stone one voxel taller than
//! any real one, or a blob above the ground, looks locally like stone; samples of the stones
//! scene had about three times the matter in the real views' sky that other stone circles of the
//! same distribution have (`examples/reference_scores.rs`, docs/training.md). This term compares
//! the mean opacity of each pixel row (the dataset's cameras have no roll, so a row is a height
//! in the scene) of a sample's rendering with the real view's alpha: matter may move sideways
//! freely, as a generator of new layouts should, but not up into the sky.

use candle_core::Tensor;

use crate::error::Result;

/// The mean over views and rows of the squared difference between the row means of
/// `generated` opacity and `real` alpha (both `(V, 1, h, w)`).
pub(super) fn height_profile_loss(generated: &Tensor, real: &Tensor) -> Result<Tensor> {
    let rows = |opacity: &Tensor| opacity.mean(3);
    Ok((rows(generated)? - rows(real)?)?.sqr()?.mean_all()?)
}

#[cfg(test)]
mod tests {
    use candle_core::{Device, Tensor};

    use super::height_profile_loss;

    /// One view of 4 rows x 4 columns from per-pixel values, row-major.
    fn view(values: [f32; 16]) -> Tensor {
        Tensor::from_vec(values.to_vec(), (1, 1, 4, 4), &Device::Cpu).unwrap()
    }

    #[test]
    fn matter_moved_sideways_costs_nothing_and_matter_moved_up_its_rows_difference() {
        // A column of matter two rows tall, standing on the bottom row.
        let real = view([
            0., 0., 0., 0., //
            0., 0., 0., 0., //
            0., 1., 0., 0., //
            0., 1., 0., 0., //
        ]);
        let sideways = view([
            0., 0., 0., 0., //
            0., 0., 0., 0., //
            0., 0., 0., 1., //
            0., 0., 0., 1., //
        ]);
        let loss = height_profile_loss(&sideways, &real).unwrap();
        assert_eq!(loss.to_scalar::<f32>().unwrap(), 0.0);
        // One row taller: the top row gains 1/4 of opacity; rows are 4, so the mean of the
        // squared row differences is (1/4)^2 / 4.
        let taller = view([
            0., 0., 0., 0., //
            0., 1., 0., 0., //
            0., 1., 0., 0., //
            0., 1., 0., 0., //
        ]);
        let loss = height_profile_loss(&taller, &real).unwrap();
        assert!((loss.to_scalar::<f32>().unwrap() - 1.0 / 64.0).abs() < 1e-7);
    }
}

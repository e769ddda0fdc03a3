//! The active set of a finer 3D scale: the voxels where its generator may change the volume.
//!
//! From [`TrainConfig::sparse_from_scale`] on, a finer scale computes
//! `V_n = up(V_{n-1}) + M_n * G_n(z_n + up(V_{n-1}))`, where the mask `M_n` is 1 within
//! [`TrainConfig::sparse_margin`] voxels (in every axis, a cube around each voxel) of a voxel
//! whose density in `up(V_{n-1})` exceeds [`TrainConfig::sparse_threshold`], and 0 elsewhere.
//! The coarser scale decides where matter may be; the finer scales refine it there and leave
//! the empty rest of the box as the coarser scale made it, so they cannot put matter in the sky.
//! The mask is computed per volume (every generated sample has its own) and is a constant to the
//! gradient.
//!
//! [`TrainConfig::sparse_from_scale`]: crate::TrainConfig::sparse_from_scale
//! [`TrainConfig::sparse_margin`]: crate::TrainConfig::sparse_margin
//! [`TrainConfig::sparse_threshold`]: crate::TrainConfig::sparse_threshold

use candle_core::{DType, Tensor};
use radiance_volume::Activation;

use crate::dilate::dilate;
use crate::error::{invalid, Result};

/// The active-set mask `(B, 1, D, H, W)` (f32, 0 or 1) of the raw volumes `(B, 4, D, H, W)`:
/// 1 within `margin` voxels (Chebyshev distance, clipped at the box's faces) of a voxel whose
/// density `sigma` (under `activation`) exceeds `threshold`.
///
/// ```
/// use candle_core::{Device, Tensor};
/// use radiance_volume::Activation;
/// use singrav::active_set::active_mask;
/// let activation = Activation::default();
/// // One dense voxel in the corner of an otherwise empty 5^3 volume.
/// let mut raw = vec![-20f32; 4 * 125];
/// raw[0] = 20.0;
/// let raw = Tensor::from_vec(raw, (1, 4, 5, 5, 5), &Device::Cpu)?;
/// let mask = active_mask(&raw, &activation, 0.1, 1)?;
/// // The corner's 2^3 neighbourhood (the margin, clipped at the faces) is active.
/// assert_eq!(mask.sum_all()?.to_scalar::<f32>()?, 8.0);
/// # Ok::<(), singrav::Error>(())
/// ```
pub fn active_mask(
    raw: &Tensor,
    activation: &Activation,
    threshold: f32,
    margin: usize,
) -> Result<Tensor> {
    let (batch, channels, d, h, w) = raw.dims5()?;
    if channels == 0 {
        return Err(invalid("volume", "has no density channel"));
    }
    // Compare raw values with the raw threshold: exact (softplus is monotonic) and cheaper than
    // applying the activation to every voxel.
    let raw_threshold = activation.raw_density(threshold).map_err(|e| {
        invalid(
            "sparse_threshold",
            format!("expected a finite density > 0: {e}"),
        )
    })?;
    let density: Vec<f32> = raw
        .narrow(1, 0, 1)?
        .to_dtype(DType::F32)?
        .flatten_all()?
        .to_vec1()?;
    let voxels = d * h * w;
    let mut mask = Vec::with_capacity(batch * voxels);
    for volume in density.chunks_exact(voxels) {
        let occupied: Vec<bool> = volume.iter().map(|&v| v > raw_threshold).collect();
        mask.extend(
            dilate(&occupied, [d, h, w], margin)
                .into_iter()
                .map(|active| if active { 1f32 } else { 0.0 }),
        );
    }
    Ok(Tensor::from_vec(mask, (batch, 1, d, h, w), raw.device())?)
}

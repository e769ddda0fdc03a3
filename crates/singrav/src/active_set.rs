//! The active set of a finer 3D scale: the voxels where its generator may change the volume.
//!
//! From [`ActiveSet::from_scale`] on, a finer scale computes
//! `V_n = up(V_{n-1}) + S_A(G_n^A(z_n + up(V_{n-1})))`, where the active set `A` is every voxel
//! within [`ActiveSet::margin`] voxels (in every axis, a cube around each voxel) of a
//! voxel whose density in `up(V_{n-1})` exceeds [`ActiveSet::threshold`]. `G_n^A` is
//! the generator run on `A` only, as submanifold layers (patch-gan's
//! `Generator3d::forward_residual_active`): each convolution computes the voxels of `A` and
//! reads the voxels outside it as zero, and BatchNorm takes its statistics over `A`; `S_A` puts
//! the result back in its voxels. The coarser scale decides where matter may be; the finer
//! scales refine it there, at a cost in proportion to `A`, and leave the empty rest of the box
//! as the coarser scale made it, so they cannot put matter in the sky. The set is computed per
//! volume (every generated sample has its own) and is a constant to the gradient.
//!
//! [`ActiveSet::from_scale`]: crate::config::ActiveSet::from_scale
//! [`ActiveSet::margin`]: crate::config::ActiveSet::margin
//! [`ActiveSet::threshold`]: crate::config::ActiveSet::threshold

use candle_core::{DType, Tensor};
use patch_gan::ActiveSites;
use radiance_volume::Activation;

use crate::error::{invalid, Result};
use radiance_volume::dilate_mask;

/// Which voxels of a finer scale are active, from the upsampled coarser volume.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ActiveSetRule {
    /// Density `sigma` above which a voxel is matter.
    pub threshold: f32,
    /// Voxels (Chebyshev distance, a cube of this half-width) around matter that are active.
    pub margin: usize,
    /// Leave the inside of matter out too: active only within `margin` of both matter and air
    /// (a shell around the surfaces). The inside of solid matter is hidden behind its surface,
    /// so refining it changes no rendering; the box's faces do not count as air.
    pub shell: bool,
}

/// The active-set mask `(B, 1, D, H, W)` (f32, 0 or 1) of the raw volumes `(B, 4, D, H, W)`:
/// 1 within `rule.margin` voxels (Chebyshev distance, clipped at the box's faces) of a voxel
/// whose density `sigma` (under `activation`) exceeds `rule.threshold` and, with `rule.shell`,
/// also within `rule.margin` voxels of one that does not.
///
/// ```
/// use candle_core::{Device, Tensor};
/// use radiance_volume::Activation;
/// use singrav::active_set::{active_mask, ActiveSetRule};
/// let activation = Activation::default();
/// // One dense voxel in the corner of an otherwise empty 5^3 volume.
/// let mut raw = vec![-20f32; 4 * 125];
/// raw[0] = 20.0;
/// let raw = Tensor::from_vec(raw, (1, 4, 5, 5, 5), &Device::Cpu)?;
/// let rule = ActiveSetRule { threshold: 0.1, margin: 1, shell: false };
/// let mask = active_mask(&raw, &activation, &rule)?;
/// // The corner's 2^3 neighbourhood (the margin, clipped at the faces) is active.
/// assert_eq!(mask.sum_all()?.to_scalar::<f32>()?, 8.0);
/// // A full volume has no surface inside the box: its shell is empty.
/// let full = Tensor::full(20f32, (1, 4, 5, 5, 5), &Device::Cpu)?;
/// let shell = ActiveSetRule { shell: true, ..rule };
/// assert_eq!(active_mask(&full, &activation, &shell)?.sum_all()?.to_scalar::<f32>()?, 0.0);
/// # Ok::<(), singrav::Error>(())
/// ```
pub fn active_mask(raw: &Tensor, activation: &Activation, rule: &ActiveSetRule) -> Result<Tensor> {
    let (active, batch, [d, h, w]) = active_voxels(raw, activation, rule)?;
    let mask = active
        .into_iter()
        .map(|a| if a { 1f32 } else { 0.0 })
        .collect();
    Ok(Tensor::from_vec(mask, (batch, 1, d, h, w), raw.device())?)
}

/// The active set of [`active_mask`] as the sites a generator with `kernel`-tap kernels runs on
/// (what training and sampling use, without a mask tensor in between).
///
/// ```
/// use candle_core::{Device, Tensor};
/// use radiance_volume::Activation;
/// use singrav::active_set::{active_sites, ActiveSetRule};
/// let mut raw = vec![-20f32; 4 * 125];
/// raw[0] = 20.0;
/// let raw = Tensor::from_vec(raw, (1, 4, 5, 5, 5), &Device::Cpu)?;
/// let rule = ActiveSetRule { threshold: 0.1, margin: 1, shell: false };
/// assert_eq!(active_sites(&raw, &Activation::default(), &rule, 3)?.len(), 8);
/// # Ok::<(), singrav::Error>(())
/// ```
pub fn active_sites(
    raw: &Tensor,
    activation: &Activation,
    rule: &ActiveSetRule,
    kernel: usize,
) -> Result<ActiveSites> {
    let (active, batch, dims) = active_voxels(raw, activation, rule)?;
    Ok(ActiveSites::new(batch, dims, kernel, &active)?)
}

/// Whether each voxel of the raw volumes `(B, 4, D, H, W)` is active under `rule`, flattened,
/// with `B` and `[D, H, W]`.
fn active_voxels(
    raw: &Tensor,
    activation: &Activation,
    rule: &ActiveSetRule,
) -> Result<(Vec<bool>, usize, [usize; 3])> {
    let (batch, channels, d, h, w) = raw.dims5()?;
    if channels == 0 {
        return Err(invalid("volume", "has no density channel"));
    }
    // Compare raw values with the raw threshold: exact (softplus is monotonic) and cheaper than
    // applying the activation to every voxel.
    let raw_threshold = activation.raw_density(rule.threshold).map_err(|e| {
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
    let mut active = Vec::with_capacity(batch * voxels);
    for volume in density.chunks_exact(voxels) {
        let occupied: Vec<bool> = volume.iter().map(|&v| v > raw_threshold).collect();
        let near_matter = dilate_mask(&occupied, [d, h, w], rule.margin)?;
        let near_air = if rule.shell {
            let air: Vec<bool> = occupied.iter().map(|&o| !o).collect();
            dilate_mask(&air, [d, h, w], rule.margin)?
        } else {
            vec![true; voxels]
        };
        active.extend(near_matter.into_iter().zip(near_air).map(|(m, a)| m && a));
    }
    Ok((active, batch, [d, h, w]))
}

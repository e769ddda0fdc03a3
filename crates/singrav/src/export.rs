//! Volumes for tools that interpolate physical density (Blender, OpenVDB's tools, `volgen
//! render`): a volume as volgen's renderer takes it, written on a finer grid so that it renders
//! there as volgen renders it.

use radiance_volume::{Activation, RadianceVolume, Resampled};
use volrender::DensityInterpolation;

use crate::error::{invalid, Result};

/// The physical volume, on a grid `factor` times finer per axis, of `rendered`, a volume as
/// volgen's renderer takes it under the density rule `density`: every fine voxel holds what
/// the renderer computes at its centre. Under
/// [`DensityInterpolation::PostActivated`] that is channel 0's raw density interpolated, then
/// activated, so an edge that falls inside a coarse voxel stays within a fine voxel (written per
/// coarse voxel it is smeared over a whole one); colour and physical density are interpolated.
/// (A renderer with density-weighted colour blends colour otherwise; the file holds colour
/// interpolated on its own, which is what the tools reading it do.)
///
/// `factor` must be odd: then the fine voxel centres include the coarse ones, so trilinear
/// interpolation over the fine grid reproduces the coarse grid's trilinear colour exactly and
/// only the density's activation between fine centres is approximated. With an even factor the
/// fine centres straddle the coarse ones and the result renders further from volgen than the
/// coarse volume itself (docs/formats.md has the measurements).
///
/// ```
/// use candle_core::{Device, Tensor};
/// use radiance_volume::{Aabb, GridDims, RadianceVolume};
/// use volrender::DensityInterpolation;
/// // Raw density 4 then -4 along x, grey: the activation's knee lies between the two voxels.
/// let raw = Tensor::new(&[4f32, -4.0, 0.5, 0.5, 0.5, 0.5, 0.5, 0.5], &Device::Cpu)?
///     .reshape((4, 1, 1, 2))?;
/// let rendered = RadianceVolume::new(raw, Aabb::CUBE)?;
/// let rule = DensityInterpolation::PostActivated { scale: 1.0, shift: 0.0 };
/// let fine = singrav::export::physical_upsampled(&rendered, rule, 3)?;
/// assert_eq!(fine.dims(), GridDims::new(3, 3, 6));
/// // The middle fine voxels sit on the coarse centres: softplus(4) and softplus(-4).
/// let sigma: Vec<f32> = fine.density()?.flatten_all()?.to_vec1()?;
/// assert!((sigma[1] - 4.01815).abs() < 1e-4 && (sigma[4] - 0.01815).abs() < 1e-4);
/// assert!(singrav::export::physical_upsampled(&rendered, rule, 2).is_err());
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn physical_upsampled(
    rendered: &RadianceVolume,
    density: DensityInterpolation,
    factor: usize,
) -> Result<RadianceVolume> {
    Ok(physical_upsampled_source(rendered, density, factor)?.to_volume()?)
}

/// [`physical_upsampled`] as a [`VolumeSource`](radiance_volume::VolumeSource) computed block
/// by block when read: what the writers take to stream a volume 27 times (`factor` 3) larger
/// than `rendered` without ever holding it.
///
/// ```
/// use candle_core::{Device, Tensor};
/// use radiance_volume::{Aabb, GridDims, RadianceVolume, VoxelRange, VolumeSource};
/// use volrender::DensityInterpolation;
/// let raw = Tensor::new(&[4f32, -4.0, 0.5, 0.5, 0.5, 0.5, 0.5, 0.5], &Device::Cpu)?
///     .reshape((4, 1, 1, 2))?;
/// let rendered = RadianceVolume::new(raw, Aabb::CUBE)?;
/// let rule = DensityInterpolation::PostActivated { scale: 1.0, shift: 0.0 };
/// let fine = singrav::export::physical_upsampled_source(&rendered, rule, 3)?;
/// assert_eq!(fine.dims(), GridDims::new(3, 3, 6));
/// // The voxel on the first coarse centre: softplus(4).
/// let sigma = fine.read_block(0..1, &VoxelRange { z: 1..2, y: 1..2, x: 1..2 })?;
/// assert!((sigma[0] - 4.01815).abs() < 1e-4);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn physical_upsampled_source(
    rendered: &RadianceVolume,
    density: DensityInterpolation,
    factor: usize,
) -> Result<Resampled> {
    if factor.is_multiple_of(2) {
        return Err(invalid(
            "upsampling factor",
            format!(
                "expected an odd factor (1 keeps the grid; 3, 5, ... keep its voxel centres \
                 among the finer grid's), got {factor}"
            ),
        ));
    }
    let fine = Resampled::finer(rendered.clone(), factor)?;
    Ok(match density.post_activation() {
        Some([scale, shift]) => fine.with_density_activation(
            Activation::default()
                .with_density_scale(scale)
                .with_density_shift(shift),
        ),
        None => fine,
    })
}

//! Volumes for tools that interpolate physical density (Blender, OpenVDB's tools, `volgen
//! render`): a volume as volgen's renderer takes it, written on a finer grid so that it renders
//! there as volgen renders it.

use radiance_volume::{Activation, GridDims, RadianceVolume};
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
    if factor % 2 == 0 {
        return Err(invalid(
            "upsampling factor",
            format!(
                "expected an odd factor (1 keeps the grid; 3, 5, ... keep its voxel centres \
                 among the finer grid's), got {factor}"
            ),
        ));
    }
    let coarse = rendered.dims();
    let fine = rendered.resample(GridDims::new(
        coarse.d * factor,
        coarse.h * factor,
        coarse.w * factor,
    ))?;
    let Some([scale, shift]) = density.post_activation() else {
        return Ok(fine);
    };
    let activation = Activation::default()
        .with_density_scale(scale)
        .with_density_shift(shift);
    let values = fine.tensor();
    let sigma = activation.apply_density(&values.narrow(0, 0, 1)?)?;
    let colour = values.narrow(0, 1, values.dim(0)? - 1)?;
    Ok(fine.with_tensor(candle_core::Tensor::cat(&[&sigma, &colour], 0)?)?)
}

//! A directly fitted volume (see [`crate::fit`]) as a 3D target for the reconstruction V*_n:
//! an exact, cheap comparison that gives every voxel a gradient, where the views give only the
//! voxels along a few rays.

use std::path::Path;

use candle_core::{Device, Tensor};
use radiance_volume::{Aabb, Activation, GridDims, RadianceVolume};

use crate::error::{invalid, Result};

/// The fitted volume at one scale's size, as opacity per voxel and opacity-weighted colour.
///
/// Both are compared rather than density and colour themselves: opacity across a voxel,
/// `1 - exp(-sigma * voxel)`, is bounded (a stone's sigma of 200 and one of 2000 look the same),
/// and colour only matters where there is matter to see.
#[derive(Debug, Clone)]
pub(super) struct FittedTarget {
    /// `(1, 1, s, s, s)`.
    opacity: Tensor,
    /// `(1, 3, s, s, s)`: the fitted colour times the fitted opacity.
    weighted_rgb: Tensor,
    /// The model's voxel edge at this scale.
    voxel: f64,
}

/// Per-voxel opacity of a physical density `(.., 1, s, s, s)` across a voxel of edge `voxel`.
fn voxel_opacity(sigma: &Tensor, voxel: f64) -> Result<Tensor> {
    Ok(((sigma * -voxel)?.exp()?.neg()? + 1.0)?)
}

impl FittedTarget {
    /// The target at edge `size`: `volume` resampled (trilinear, cell-centred) over the same box.
    pub fn new(volume: &RadianceVolume, size: usize, device: &Device) -> Result<Self> {
        let resampled = volume.resample(GridDims::cube(size))?;
        let physical = resampled
            .tensor()
            .narrow(0, 0, 4)?
            .unsqueeze(0)?
            .to_device(device)?;
        // Opacity across a voxel does not depend on the units: the fit's voxel is measured in
        // its box (a scene's own coordinates under --bounds), the model's in [-1, 1]^3.
        let fitted_voxel = f64::from(volume.aabb().size().min_element()) / size as f64;
        let opacity = voxel_opacity(&physical.narrow(1, 0, 1)?, fitted_voxel)?;
        let weighted_rgb = physical.narrow(1, 1, 3)?.broadcast_mul(&opacity)?;
        Ok(Self {
            opacity,
            weighted_rgb,
            voxel: 2.0 / size as f64,
        })
    }

    /// The fitted volume as the 3D critic sees volumes: `(1, 1, s, s, s)` opacity per voxel,
    /// and with `colour` `(1, 4, s, s, s)`, opacity-weighted colour after it (see
    /// [`FittedTarget::volume_features`]).
    pub fn features(&self, colour: bool) -> Result<Tensor> {
        if colour {
            Ok(Tensor::cat(&[&self.opacity, &self.weighted_rgb], 1)?)
        } else {
            Ok(self.opacity.clone())
        }
    }

    /// The same features of raw generated volumes `(B, 4, s, s, s)`, colour weighted by each
    /// volume's own opacity; differentiable. They are bounded in [0, 1], whatever the
    /// densities.
    pub fn volume_features(
        &self,
        raw: &Tensor,
        activation: &Activation,
        colour: bool,
    ) -> Result<Tensor> {
        let physical = activation.apply(raw)?;
        let opacity = voxel_opacity(&physical.narrow(1, 0, 1)?, self.voxel)?;
        if !colour {
            return Ok(opacity);
        }
        let rgb = physical.narrow(1, 1, 3)?.broadcast_mul(&opacity)?;
        Ok(Tensor::cat(&[&opacity, &rgb], 1)?)
    }

    /// The mean squared difference of opacity plus that of opacity-weighted colour, the
    /// reconstruction's colour weighted by the *fitted* opacity (so that colour in what should
    /// be empty space costs nothing), for a raw `(1, 4, s, s, s)` reconstruction.
    pub fn loss(&self, raw: &Tensor, activation: &Activation) -> Result<Tensor> {
        let physical = activation.apply(raw)?;
        let opacity = voxel_opacity(&physical.narrow(1, 0, 1)?, self.voxel)?;
        let rgb = physical.narrow(1, 1, 3)?.broadcast_mul(&self.opacity)?;
        let opacity_term = (opacity - &self.opacity)?.sqr()?.mean_all()?;
        let colour_term = (rgb - &self.weighted_rgb)?.sqr()?.mean_all()?;
        Ok((opacity_term + colour_term)?)
    }
}

/// Loads a fitted volume for training, checking what training assumes: the box of the model's
/// cube (`[-1, 1]^3`, or in a scene's coordinates the cube of its `--bounds`), a cubic grid,
/// density and RGB channels.
pub(crate) fn load_fitted(path: &Path, cube: Aabb) -> Result<RadianceVolume> {
    let volume = RadianceVolume::load_safetensors(path)?;
    let dims = volume.dims();
    let why = if volume.aabb() != cube {
        Some(format!(
            "its box is {:?}..{:?}; training's cube is {:?}..{:?} (fit with the run's --bounds)",
            volume.aabb().min.to_array(),
            volume.aabb().max.to_array(),
            cube.min.to_array(),
            cube.max.to_array()
        ))
    } else if dims.d != dims.h || dims.h != dims.w {
        Some(format!("its grid {:?} is not cubic", dims.xyz()))
    } else if volume.channel_count() < 4 {
        Some(format!(
            "it has {} channels; expected density and RGB",
            volume.channel_count()
        ))
    } else {
        None
    };
    match why {
        Some(why) => Err(invalid(format!("fitted volume {}", path.display()), why)),
        None => Ok(volume),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn loss_is_zero_for_the_fitted_volume_itself_and_grows_with_a_difference() -> Result<()> {
        let activation = Activation::default()
            .with_density_scale(25.0)
            .with_density_shift(-4.0);
        let raw = Tensor::randn(0f32, 2.0, (1, 4, 6, 6, 6), &Device::Cpu)?;
        let volume = RadianceVolume::from_raw(&raw.squeeze(0)?, Aabb::CUBE, &activation)?;
        let target = FittedTarget::new(&volume, 6, &Device::Cpu)?;
        let same = target.loss(&raw, &activation)?.to_scalar::<f32>()?;
        assert!(same < 1e-10, "{same}");
        // What the 3D critic sees of the fitted volume and of the same raw volume generated.
        for (colour, channels) in [(false, 1), (true, 4)] {
            let real = target.features(colour)?;
            let generated = target.volume_features(&raw, &activation, colour)?;
            assert_eq!(real.dims(), &[1, channels, 6, 6, 6]);
            let diff = (real - generated)?.abs()?.max_all()?.to_scalar::<f32>()?;
            assert!(diff < 1e-6, "{diff}");
        }
        let other = target
            .loss(&(raw + 1.0)?, &activation)?
            .to_scalar::<f32>()?;
        assert!(other > 1e-3, "{other}");
        Ok(())
    }

    #[test]
    fn opacity_is_one_minus_transmittance_across_a_voxel() -> Result<()> {
        let sigma = Tensor::new(&[0f32, 1.0, 100.0], &Device::Cpu)?;
        let got: Vec<f32> = voxel_opacity(&sigma, 0.5)?.to_vec1()?;
        let want = [0.0, 1.0 - (-0.5f32).exp(), 1.0];
        for (g, w) in got.iter().zip(want) {
            assert!((g - w).abs() < 1e-6, "{g} vs {w}");
        }
        Ok(())
    }
}

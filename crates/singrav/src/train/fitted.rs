//! A directly fitted volume (see [`volume_fit`]) as a 3D target for the reconstruction V*_n:
//! an exact, cheap comparison that gives every voxel a gradient, where the views give only the
//! voxels along a few rays ([`super::prepare`] says where a run gets it).

use std::path::Path;

use candle_core::{Device, Tensor};
use radiance_volume::{resample_tensor, Aabb, Activation, GridDims, RadianceVolume};
use rgbd_dataset::Dataset;
use volrender::DensityInterpolation;
use volume_fit::{fit_volume, FitProgress, FittedVolume};

use crate::config::TrainConfig;
use crate::error::{invalid, Result};

/// The range raw density is compared over in post-activated runs. Beyond it a voxel renders the
/// same (with every preset's activation, `25 softplus(raw - 4)`, raw -8 is empty to 1e-4 of
/// opacity across a `tiny` voxel and raw 16 opaque), but where an edge falls between two voxels
/// still depends on the empty one's raw value: the stones' 28^3 post-activated fit clamped to
/// [-4, 12] renders 1.5 dB below itself, clamped to [-8, 16] 0.02 dB (0.2 and 0.0 dB on the
/// scene made in Blender).
const RAW_DENSITY_RANGE: (f64, f64) = (-8.0, 16.0);

/// The fitted volume at one scale's size, as opacity per voxel (or, for post-activated runs,
/// raw density) and opacity-weighted colour.
///
/// Opacity is compared rather than density itself: opacity across a voxel,
/// `1 - exp(-sigma * voxel)`, is bounded (a stone's sigma of 200 and one of 2000 look the same),
/// and colour only matters where there is matter to see. A post-activated run's renderer
/// interpolates raw density, and where between two voxels an edge falls depends on both raw
/// values even where each voxel's opacity is 0 or 1, so those runs compare raw density over
/// [`RAW_DENSITY_RANGE`] instead.
#[derive(Debug, Clone)]
pub(super) struct FittedTarget {
    /// `(1, 1, s, s, s)`.
    opacity: Tensor,
    /// `(1, 3, s, s, s)`: the fitted colour times the fitted opacity.
    weighted_rgb: Tensor,
    /// The model's voxel edge at this scale.
    voxel: f64,
    /// Post-activated runs: `(1, 1, s, s, s)`, the fitted raw density in the model's units,
    /// clamped to [`RAW_DENSITY_RANGE`], resampled as the renderer interpolates it.
    raw_density: Option<Tensor>,
}

/// The raw density whose activation by `[scale, shift]` is `volume`'s physical density
/// ([`Activation::raw_density`]), in the units of the model's cube `[-1, 1]^3`, clamped to
/// [`RAW_DENSITY_RANGE`] (softplus never reaches 0, so empty voxels get the floor) and
/// resampled to `size`.
fn raw_density_target(
    volume: &RadianceVolume,
    size: usize,
    [scale, shift]: [f32; 2],
) -> Result<Tensor> {
    let activation = Activation::default()
        .with_density_scale(scale)
        .with_density_shift(shift);
    // Density is per unit length: the fit's box has edge `L`, the model's cube edge 2.
    let to_model = volume.aabb().size().min_element() / 2.0;
    let (low, high) = RAW_DENSITY_RANGE;
    let voxels = volume.dims().xyz().iter().product::<usize>();
    let raw = volume.with_values(|values| {
        values[..voxels]
            .iter()
            .map(|&sigma| match sigma * to_model {
                empty if empty <= 0.0 => Ok(low as f32),
                sigma => Ok(f64::from(activation.raw_density(sigma)?).clamp(low, high) as f32),
            })
            .collect::<Result<Vec<f32>>>()
    })??;
    let dims = volume.dims();
    let raw = Tensor::from_vec(raw, (1, dims.d, dims.h, dims.w), volume.tensor().device())?;
    Ok(resample_tensor(&raw, GridDims::cube(size))?.unsqueeze(0)?)
}

/// What the 3D critic sees of a volume ([`crate::config::Critics`]): per-voxel opacity, with
/// `colour` opacity-weighted colour after it, and with `seen_from_above` every channel weighted
/// by the transmittance of the voxels above (the matter a ray straight down meets).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) struct VolumeSight {
    pub colour: bool,
    pub seen_from_above: bool,
    /// The voxels' positions (the CSG grid) as three more channels.
    pub positions: bool,
}

impl VolumeSight {
    pub fn of(critics: &crate::config::Critics) -> Self {
        Self {
            colour: critics.volume_colour,
            seen_from_above: critics.volume_seen_from_above,
            positions: critics.volume_positions,
        }
    }

    /// The channels the 3D critic sees: opacity, then with `colour` three of weighted colour,
    /// then with `positions` three of position.
    pub fn channels(&self) -> usize {
        1 + 3 * usize::from(self.colour) + 3 * usize::from(self.positions)
    }
}

/// The transmittance `(B, 1, s, s, s)` from the top of the box (the last z index, the box's z
/// axis being up) down to just above each voxel, of a per-voxel opacity `(B, 1, s, s, s)`: the
/// product of `1 - opacity` over the voxels above. Differentiable; the product is taken as the
/// exponential of a sum of logarithms, each `1 - opacity` floored at `1e-6` so that an opaque
/// voxel's logarithm stays finite.
fn transmittance_above(opacity: &Tensor) -> Result<Tensor> {
    let log_clear = (opacity.neg()? + 1.0)?.clamp(1e-6, 1.0)?.log()?;
    // z last, then a product with the matrix of ones where z' > z sums each column above z.
    let z_last = log_clear.transpose(2, 4)?.contiguous()?;
    let n = z_last.dim(4)?;
    let (dtype, device) = (z_last.dtype(), z_last.device());
    let strictly_above = (Tensor::tril2(n, dtype, device)? - Tensor::eye(n, dtype, device)?)?;
    let above = z_last.broadcast_matmul(&strictly_above)?;
    Ok(above.exp()?.transpose(2, 4)?.contiguous()?)
}

/// `opacity` and its weighted colour `weighted_rgb` as `sight` sees them.
fn sighted(opacity: &Tensor, weighted_rgb: Option<&Tensor>, sight: VolumeSight) -> Result<Tensor> {
    let seen = if sight.seen_from_above {
        Some(transmittance_above(opacity)?)
    } else {
        None
    };
    let weigh = |t: &Tensor| -> Result<Tensor> {
        match &seen {
            Some(t_above) => Ok(t.broadcast_mul(t_above)?),
            None => Ok(t.clone()),
        }
    };
    let mut channels = vec![weigh(opacity)?];
    if let (Some(rgb), true) = (weighted_rgb, sight.colour) {
        channels.push(weigh(rgb)?);
    }
    if sight.positions {
        let (batch, _, d, h, w) = opacity.dims5()?;
        let grid = csg_embed::csg_grid_3d(d, h, w, opacity.device())?
            .to_dtype(opacity.dtype())?
            .unsqueeze(0)?;
        channels.push(grid.broadcast_as((batch, 3, d, h, w))?.contiguous()?);
    }
    Ok(Tensor::cat(&channels, 1)?)
}

/// Per-voxel opacity of a physical density `(.., 1, s, s, s)` across a voxel of edge `voxel`.
fn voxel_opacity(sigma: &Tensor, voxel: f64) -> Result<Tensor> {
    Ok(((sigma * -voxel)?.exp()?.neg()? + 1.0)?)
}

impl FittedTarget {
    /// The target at edge `size`: `volume` resampled (trilinear, cell-centred) over the same box;
    /// `density` is the run's rule (post-activated runs compare raw density).
    pub fn new(
        volume: &RadianceVolume,
        size: usize,
        density: DensityInterpolation,
        device: &Device,
    ) -> Result<Self> {
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
        let raw_density = density
            .post_activation()
            .map(|rule| -> Result<Tensor> {
                Ok(raw_density_target(volume, size, rule)?.to_device(device)?)
            })
            .transpose()?;
        Ok(Self {
            opacity,
            weighted_rgb,
            voxel: 2.0 / size as f64,
            raw_density,
        })
    }

    /// The fitted volume as the 3D critic sees volumes: `(1, 1, s, s, s)` opacity per voxel,
    /// and with `sight.colour` `(1, 4, s, s, s)`, opacity-weighted colour after it, weighted
    /// as `sight` says (see [`FittedTarget::volume_features`]).
    pub fn features(&self, sight: VolumeSight) -> Result<Tensor> {
        sighted(&self.opacity, Some(&self.weighted_rgb), sight)
    }

    /// The same features of raw generated volumes `(B, 4, s, s, s)`, colour weighted by each
    /// volume's own opacity; differentiable. They are bounded in [0, 1], whatever the
    /// densities.
    pub fn volume_features(
        &self,
        raw: &Tensor,
        activation: &Activation,
        sight: VolumeSight,
    ) -> Result<Tensor> {
        let physical = activation.apply(raw)?;
        let opacity = voxel_opacity(&physical.narrow(1, 0, 1)?, self.voxel)?;
        let rgb = if sight.colour {
            Some(physical.narrow(1, 1, 3)?.broadcast_mul(&opacity)?)
        } else {
            None
        };
        sighted(&opacity, rgb.as_ref(), sight)
    }

    /// The mean squared difference of opacity (post-activated runs: of raw density over
    /// [`RAW_DENSITY_RANGE`]) plus that of opacity-weighted colour, the reconstruction's colour
    /// weighted by the *fitted* opacity (so that colour in what should be empty space costs
    /// nothing), for a raw `(1, 4, s, s, s)` reconstruction.
    pub fn loss(&self, raw: &Tensor, activation: &Activation) -> Result<Tensor> {
        let raw_sigma = raw.narrow(1, 0, 1)?;
        let density_term = match &self.raw_density {
            Some(target) => {
                let (low, high) = RAW_DENSITY_RANGE;
                (raw_sigma.clamp(low, high)? - target)?.sqr()?.mean_all()?
            }
            None => {
                let sigma = activation.apply_density(&raw_sigma)?;
                let opacity = voxel_opacity(&sigma, self.voxel)?;
                (opacity - &self.opacity)?.sqr()?.mean_all()?
            }
        };
        // The colour half only: the density channel comes back raw and is left out.
        let colour = activation.apply_colour(raw)?.narrow(1, 1, 3)?;
        let rgb = colour.broadcast_mul(&self.opacity)?;
        let colour_term = (rgb - &self.weighted_rgb)?.sqr()?.mean_all()?;
        Ok((density_term + colour_term)?)
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

/// The direct fit a run of `config` compares with when given none: `dataset`'s training views
/// (all but those `config.run.holdout` keeps out, so held-out views stay held out), in the
/// scene's coordinates, fitted as [`TrainConfig::fit_config`] says, for `steps` steps instead of
/// its budget when given. `observer` sees the fit's progress.
///
/// ```no_run
/// let config = singrav::TrainConfig::preset("tiny")?;
/// let data = rgbd_dataset::Dataset::load("data/stones".as_ref(), config.rendering.background)?;
/// let fitted = singrav::train::fit_training_target(&config, &data, Some(300), &mut |_| {})?;
/// fitted.volume.save_safetensors("fitted.safetensors")?;
/// # Ok::<(), singrav::Error>(())
/// ```
pub fn fit_training_target(
    config: &TrainConfig,
    dataset: &Dataset,
    steps: Option<usize>,
    observer: &mut dyn FnMut(&FitProgress),
) -> Result<FittedVolume> {
    let defaults = config.fit_config();
    let fit_config = volume_fit::FitConfig {
        budget: steps.map_or(defaults.budget, volume_fit::FitBudget::Steps),
        ..defaults
    };
    let training = super::prepare::training_views(config, dataset)?;
    Ok(fit_volume(dataset, &training, &fit_config, observer)?)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn transmittance_above_is_the_product_of_the_clear_shares_above() -> Result<()> {
        // Two columns of 3 voxels, z = 0 at the bottom: opacities (bottom to top) 0.5, 0.2, 0.4
        // and 0, 1, 0.5.
        let opacity = Tensor::from_vec(
            vec![0.5f32, 0.0, 0.2, 1.0, 0.4, 0.5],
            (1, 1, 3, 1, 2),
            &Device::Cpu,
        )?;
        let got: Vec<f32> = transmittance_above(&opacity)?.flatten_all()?.to_vec1()?;
        // Top: 1; middle: 1 - top; bottom: (1 - top)(1 - middle) (an opaque voxel: 1e-6).
        let want = [0.6 * 0.8, 0.5 * 1e-6, 0.6, 0.5, 1.0, 1.0];
        for (g, w) in got.iter().zip(want) {
            assert!((f64::from(*g) - w).abs() < 1e-6, "{got:?} against {want:?}");
        }
        Ok(())
    }

    #[test]
    fn loss_is_zero_for_the_fitted_volume_itself_and_grows_with_a_difference() -> Result<()> {
        let activation = Activation::default()
            .with_density_scale(25.0)
            .with_density_shift(-4.0);
        let raw = Tensor::randn(0f32, 2.0, (1, 4, 6, 6, 6), &Device::Cpu)?;
        let volume = RadianceVolume::from_raw(&raw.squeeze(0)?, Aabb::CUBE, &activation)?;
        let target = FittedTarget::new(&volume, 6, DensityInterpolation::Physical, &Device::Cpu)?;
        let same = target.loss(&raw, &activation)?.to_scalar::<f32>()?;
        assert!(same < 1e-10, "{same}");
        // What the 3D critic sees of the fitted volume and of the same raw volume generated.
        for (colour, seen_from_above, positions, channels) in [
            (false, false, false, 1),
            (true, false, false, 4),
            (false, true, false, 1),
            (true, true, false, 4),
            (false, true, true, 4),
            (true, true, true, 7),
        ] {
            let sight = VolumeSight {
                colour,
                seen_from_above,
                positions,
            };
            assert_eq!(sight.channels(), channels);
            let real = target.features(sight)?;
            let generated = target.volume_features(&raw, &activation, sight)?;
            assert_eq!(real.dims(), &[1, channels, 6, 6, 6]);
            if positions {
                // The last three channels are the CSG grid: x along W, from -1 + 1/6 up.
                let x = real
                    .narrow(1, channels - 3, 1)?
                    .flatten_all()?
                    .to_vec1::<f32>()?;
                let grid = csg_embed::csg_grid_3d(6, 6, 6, &Device::Cpu)?;
                let want = grid.narrow(0, 0, 1)?.flatten_all()?.to_vec1::<f32>()?;
                assert_eq!(x, want);
            }
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
    fn post_activated_runs_compare_raw_density_recovered_in_the_models_units() -> Result<()> {
        let activation = Activation::default()
            .with_density_scale(25.0)
            .with_density_shift(-4.0);
        let density = DensityInterpolation::post_activated_if(true, 25.0, -4.0);
        // Raw values from -12 to 20, scattered over the grid (a fixed sequence: every run tests
        // values beyond both ends of the range).
        let values: Vec<f32> = (0..4 * 216)
            .map(|i| (i as f32 * 0.618_034).fract() * 32.0 - 12.0)
            .collect();
        let raw = Tensor::from_vec(values, (1, 4, 6, 6, 6), &Device::Cpu)?;
        // A fit in a scene box of edge 4 holds density per scene unit: half the model's, whose
        // cube has edge 2.
        let scene_box = Aabb::try_new(glam::Vec3::splat(-1.0), glam::Vec3::splat(3.0))?;
        let physical = activation.apply(&raw.squeeze(0)?)?;
        let in_scene_units = Tensor::cat(
            &[
                (physical.narrow(0, 0, 1)? * 0.5)?,
                physical.narrow(0, 1, 3)?,
            ],
            0,
        )?;
        let volume = RadianceVolume::new(in_scene_units, scene_box)?;
        let target = FittedTarget::new(&volume, 6, density, &Device::Cpu)?;
        let recovered: Vec<f32> = target
            .raw_density
            .as_ref()
            .expect("a post-activated target")
            .flatten_all()?
            .to_vec1()?;
        let (low, high) = RAW_DENSITY_RANGE;
        let want: Vec<f32> = raw.narrow(1, 0, 1)?.flatten_all()?.to_vec1()?;
        assert!(want.iter().any(|&w| f64::from(w) < low - 1.0));
        assert!(want.iter().any(|&w| f64::from(w) > high + 1.0));
        // The f32 activation keeps about 6e-8 / softplus(raw - 4) of relative precision, so
        // near the floor (softplus(-12) = 6e-6) raw comes back to about 1e-2.
        for (got, want) in recovered.iter().zip(&want) {
            let want = f64::from(*want).clamp(low, high);
            let tolerance = 1e-3 + 1e-7 / (want - 4.0).exp().ln_1p();
            assert!(
                (f64::from(*got) - want).abs() < tolerance,
                "{got} vs {want}"
            );
        }
        let same = target.loss(&raw, &activation)?.to_scalar::<f32>()?;
        assert!(same < 1e-5, "{same}");
        // Past the range nothing changes (opaque voxels made more opaque); inside it the loss
        // sees the raw value itself, even where opacity across the voxel is already near 1.
        let density = raw.narrow(1, 0, 1)?;
        let beyond = (&density + ((&density - high)?.relu()? * 10.0)?)?;
        let pushed = Tensor::cat(&[&beyond, &raw.narrow(1, 1, 3)?], 1)?;
        let unchanged = target.loss(&pushed, &activation)?.to_scalar::<f32>()?;
        let shifted = target
            .loss(&(raw.clone() + 0.5)?, &activation)?
            .to_scalar::<f32>()?;
        assert!(unchanged < 1e-6, "{unchanged}");
        assert!(shifted > 0.1 && shifted < 0.25, "{shifted}");
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

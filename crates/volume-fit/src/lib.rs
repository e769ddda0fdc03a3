//! Direct fitting: multi-view RGB-D images to one radiance volume, by gradient descent through
//! the differentiable renderer, as DVGO and Plenoxels reconstruct a scene (no networks).
//!
//! A fit optimises a raw `(4, s, s, s)` grid under the same [`Activation`] the SinGRAV
//! generators use, so a fitted volume is directly comparable with (and usable as a target for)
//! a trained pyramid's volumes:
//!
//! - each step renders a random batch of rays drawn from all training pixels and takes one
//!   Adam step on `lambda_color mse(colour) + lambda_depth mse(depth) + lambda_opacity
//!   mse(opacity)` plus total variation ([`Regularisers`]), the depth term weighted by the
//!   dataset's depth mask (holes count 0);
//! - coarse to fine: the grid starts at `start_size` and grows geometrically to `size` over the
//!   first `growth_until` of the budget (trilinear resampling of the raw values);
//! - an occupancy mask, refreshed every `occupancy_every` steps, kills voxels farther than one
//!   voxel from any voxel of opacity `occupancy_threshold`: they render as exactly empty, so the
//!   renderer's empty-space skipping leaps over them, and they are not updated;
//! - the learning rate decays exponentially from `learning_rate` to `final_learning_rate`.
//!
//! ```
//! use rgbd_dataset::{write_dataset, Dataset, DatasetSpec};
//! use volume_fit::{fit_volume, view_psnr, FitBudget, FitConfig};
//! let dir = tempfile::tempdir()?;
//! let spec = DatasetSpec { views: 6, resolution: 16, grid: 16, seed: 1 };
//! write_dataset(&rgbd_dataset::scenes::StandingStones::new(1), dir.path(), &spec)?;
//! let data = Dataset::load(dir.path(), [1.0; 3])?;
//! let config = FitConfig { size: 12, budget: FitBudget::Steps(150), rays_per_step: 1024, ..FitConfig::default() };
//! let fitted = fit_volume(&data, &[0, 1, 2, 3, 4, 5], &config, &mut |_| {})?;
//! assert_eq!(fitted.volume.dims().xyz(), [12, 12, 12]);
//! let psnr = view_psnr(&fitted.volume, &data, &[0], &config)?;
//! assert!(psnr[0] > 15.0, "{psnr:?}"); // a grey fog scores about 9 dB
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

mod error;
mod grid;
mod rays;

use std::time::Instant;

use candle_core::{Device, Tensor, Var};
use radiance_volume::{Aabb, Activation, RadianceVolume};
use rand::SeedableRng;
use volrender::{render, Camera, DensityInterpolation, Rays, RenderConfig, Sampler};

use rgbd_dataset::Dataset;

use crate::error::invalid;

pub use error::{Error, Result};
pub use grid::Regularisers;

use grid::{FitGrid, CHANNELS};
use rays::RayBank;

/// How long a fit runs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum FitBudget {
    /// A fixed number of steps (reproducible from the seed).
    Steps(usize),
    /// Wall-clock seconds (the schedule follows elapsed time, so results vary with the machine).
    Seconds(f64),
}

/// The settings of a fit. The defaults are what docs/fit.md measured on the built-in scenes.
#[derive(Debug, Clone, PartialEq)]
pub struct FitConfig {
    /// Edge of the final grid in voxels.
    pub size: usize,
    /// Edge of the grid the fit starts from (a fit with a smaller `size` starts at `size`).
    pub start_size: usize,
    /// Fraction of the budget by which the grid has grown to `size`.
    pub growth_until: f32,
    /// How long the fit runs.
    pub budget: FitBudget,
    /// Rays per step, drawn uniformly from all training pixels.
    pub rays_per_step: usize,
    /// Adam's learning rate on raw values at the start.
    pub learning_rate: f32,
    /// The learning rate at the end of the budget (exponential decay in between).
    pub final_learning_rate: f32,
    /// Weight of the colour mse.
    pub lambda_color: f32,
    /// Weight of the depth mse (world units); ignored when `use_depth` is off.
    pub lambda_depth: f32,
    /// Weight of the opacity (alpha) mse.
    pub lambda_opacity: f32,
    /// Total variation weights.
    pub regularisers: Regularisers,
    /// Where rays are sampled: 2 per voxel crossed (the renderer's `PerVoxel`) by default;
    /// `Uniform` as SinGRAV's training renders, where a fit must match what the model renders.
    pub sampler: Sampler,
    /// Density everywhere at the start, per world length.
    pub initial_sigma: f32,
    /// Opacity across one voxel below which a voxel (and no neighbour) counts as empty.
    pub occupancy_threshold: f32,
    /// Steps between refreshes of the occupancy mask (0: never).
    pub occupancy_every: usize,
    /// Raw to physical mapping (the training configuration's, so fits and generators agree).
    pub activation: Activation,
    /// What transparent pixels were composited on (the dataset's loading background).
    pub background: [f32; 3],
    /// The world box the grid covers.
    pub aabb: Aabb,
    /// Supervise depth.
    pub use_depth: bool,
    /// Seed of the ray draws.
    pub seed: u64,
    /// Render with post-activated density (volrender's `DensityInterpolation::PostActivated`
    /// with `activation`'s scale and shift, DVGO's rule): samples activate the interpolated raw
    /// density, so the grid holds edges sharper than its voxels. The fit then optimises and
    /// renders raw density ([`FittedVolume::rendered`]); [`FittedVolume::volume`] stays
    /// physical per voxel (`volgen fit` writes it 3x finer by default,
    /// `singrav::export::physical_upsampled`).
    pub post_activation: bool,
}

impl Default for FitConfig {
    fn default() -> Self {
        Self {
            size: 64,
            start_size: 24,
            growth_until: 0.4,
            budget: FitBudget::Steps(1000),
            rays_per_step: 8192,
            learning_rate: 0.1,
            final_learning_rate: 0.01,
            lambda_color: 10.0,
            lambda_depth: 1.2,
            lambda_opacity: 1.0,
            regularisers: Regularisers {
                tv_density: 0.0,
                tv_colour: 0.0,
            },
            sampler: Sampler::PerVoxel { per_voxel: 2 },
            initial_sigma: 0.1,
            occupancy_threshold: 1e-3,
            occupancy_every: 50,
            // SinGRAV's activation and white background, so a default fit compares directly
            // with (and can be a target for) a SinGRAV run's volumes.
            activation: Activation::default()
                .with_density_scale(25.0)
                .with_density_shift(-4.0),
            background: [1.0, 1.0, 1.0],
            aabb: Aabb::CUBE,
            use_depth: true,
            seed: 0,
            post_activation: false,
        }
    }
}

impl FitConfig {
    /// Checks the settings, naming the first that is out of range.
    pub fn validate(&self) -> Result<()> {
        let checks = [
            (self.size >= 2, "size", "at least 2 voxels"),
            (self.start_size >= 2, "start_size", "at least 2 voxels"),
            (
                (0.0..=1.0).contains(&self.growth_until),
                "growth_until",
                "a fraction in [0, 1]",
            ),
            (
                match self.budget {
                    FitBudget::Steps(n) => n > 0,
                    FitBudget::Seconds(s) => s > 0.0 && s.is_finite(),
                },
                "budget",
                "a positive number of steps or seconds",
            ),
            (self.rays_per_step > 0, "rays_per_step", "at least 1"),
            (
                self.learning_rate > 0.0 && self.final_learning_rate > 0.0,
                "learning_rate",
                "positive start and final rates",
            ),
            (
                [self.lambda_color, self.lambda_depth, self.lambda_opacity]
                    .iter()
                    .chain([&self.regularisers.tv_density, &self.regularisers.tv_colour])
                    .all(|w| *w >= 0.0 && w.is_finite()),
                "loss weights",
                "finite and >= 0",
            ),
            (
                match self.sampler {
                    Sampler::PerVoxel { per_voxel: n }
                    | Sampler::Uniform { samples: n }
                    | Sampler::UniformLeft { samples: n } => n > 0,
                },
                "sampler",
                "at least 1 sample",
            ),
            (
                self.initial_sigma > 0.0 && self.initial_sigma.is_finite(),
                "initial_sigma",
                "a positive density",
            ),
            (
                (0.0..1.0).contains(&self.occupancy_threshold),
                "occupancy_threshold",
                "an opacity in [0, 1)",
            ),
        ];
        match checks.iter().find(|(ok, _, _)| !ok) {
            Some((_, what, expected)) => Err(invalid(
                format!("fit setting {what}"),
                format!("expected {expected}"),
            )),
            None => Ok(()),
        }
    }

    /// The renderer a fit (and its evaluation) uses at grid edge `size`.
    fn render_config(&self) -> RenderConfig {
        RenderConfig::default()
            .with_sampler(self.sampler)
            .with_skip_empty(true)
            .with_background(self.background)
            .with_aabb(self.aabb)
            .with_density(self.density_interpolation())
    }

    /// The renderer's density rule: post-activated with the fit's activation, or physical.
    ///
    /// ```
    /// use volume_fit::FitConfig;
    /// let config = FitConfig { post_activation: true, ..FitConfig::default() };
    /// let [scale, shift] = config.density_interpolation().post_activation().unwrap();
    /// assert_eq!((scale, shift), (config.activation.density_scale, config.activation.density_shift));
    /// assert!(FitConfig::default().density_interpolation().post_activation().is_none());
    /// ```
    pub fn density_interpolation(&self) -> DensityInterpolation {
        DensityInterpolation::post_activated_if(
            self.post_activation,
            self.activation.density_scale,
            self.activation.density_shift,
        )
    }

    /// The grid edge at budget fraction `fraction`: geometric steps from `start_size` to
    /// `size`, one per doubling of the voxel count, ending at `growth_until`.
    fn size_at(&self, fraction: f32) -> usize {
        if self.start_size >= self.size || fraction >= self.growth_until {
            return self.size;
        }
        let ratio = self.size as f32 / self.start_size as f32;
        // One stage per doubling of the voxel count (a factor 2^(1/3) on the edge).
        let stages = (3.0 * ratio.log2()).ceil().max(1.0);
        let stage = (fraction / self.growth_until * stages).floor();
        ((self.start_size as f32) * ratio.powf(stage / stages)).round() as usize
    }

    fn learning_rate_at(&self, fraction: f32) -> f32 {
        self.learning_rate * (self.final_learning_rate / self.learning_rate).powf(fraction)
    }
}

/// What the observer of a fit sees after every step.
#[derive(Debug, Clone)]
pub struct FitProgress {
    /// Steps taken.
    pub step: usize,
    /// Fraction of the budget used, in [0, 1].
    pub fraction: f32,
    /// The grid's current edge.
    pub size: usize,
    /// The step's colour PSNR over its ray batch, in dB.
    pub batch_psnr: f64,
    /// The fraction of voxels that are live (not skipped as empty).
    pub live_fraction: f32,
}

/// A fitted volume and how the fit went.
#[derive(Debug, Clone)]
pub struct FittedVolume {
    /// The physical volume (density exactly 0 where the occupancy mask found nothing).
    pub volume: RadianceVolume,
    /// The volume as the fit's renderer takes it, what [`view_psnr`] and [`render_views`]
    /// render: `volume` itself, or with [`FitConfig::post_activation`] the same with raw
    /// density in channel 0.
    pub rendered: RadianceVolume,
    /// The raw values `(4, s, s, s)` the fit optimised, under the config's activation (what
    /// [`fit_volume_from`] starts from). Voxels the occupancy mask killed keep their last raw
    /// values here, where `volume` and `rendered` hold them empty.
    pub raw: Tensor,
    /// Steps taken.
    pub steps: usize,
    /// Wall-clock seconds of the fit.
    pub seconds: f64,
    /// The fraction of voxels live at the end.
    pub live_fraction: f32,
}

/// Fits a radiance volume to the views `training` of `dataset` (loaded with the config's
/// background), calling `observer` after every step.
///
/// Errors on bad settings, an empty or out-of-range view list, or a renderer failure.
pub fn fit_volume(
    dataset: &Dataset,
    training: &[usize],
    config: &FitConfig,
    observer: &mut dyn FnMut(&FitProgress),
) -> Result<FittedVolume> {
    config.validate()?;
    let grid = FitGrid::new(
        config.size_at(0.0),
        config.activation,
        config.initial_sigma,
        config.post_activation,
    )?;
    run_fit(dataset, training, config, grid, observer)
}

/// Continues a fit from the raw values `initial` `(4, s, s, s)` (raw density and colour under
/// the config's activation, as a SinGRAV pyramid's raw volume holds them), with `s` the
/// config's `size`: the grid does not grow, and the config's budget, rates, losses and
/// occupancy mask apply as in [`fit_volume`]. With `occupancy_every` 0 every voxel stays live,
/// so [`FittedVolume::raw`] renders exactly as the fit rendered.
///
/// ```
/// use candle_core::{Device, Tensor};
/// use rgbd_dataset::{write_dataset, Dataset, DatasetSpec};
/// use volume_fit::{fit_volume_from, FitBudget, FitConfig};
/// let dir = tempfile::tempdir()?;
/// let spec = DatasetSpec { views: 4, resolution: 12, grid: 12, seed: 1 };
/// write_dataset(&rgbd_dataset::scenes::StandingStones::new(1), dir.path(), &spec)?;
/// let data = Dataset::load(dir.path(), [1.0; 3])?;
/// let config = FitConfig { size: 8, budget: FitBudget::Steps(20), rays_per_step: 256, occupancy_every: 0, ..FitConfig::default() };
/// let start = Tensor::zeros((4, 8, 8, 8), candle_core::DType::F32, &Device::Cpu)?;
/// let fitted = fit_volume_from(&data, &[0, 1, 2, 3], &config, &start, &mut |_| {})?;
/// assert_eq!(fitted.raw.dims(), &[4, 8, 8, 8]);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
///
/// Errors as [`fit_volume`] does, and on a start of another shape.
pub fn fit_volume_from(
    dataset: &Dataset,
    training: &[usize],
    config: &FitConfig,
    initial: &Tensor,
    observer: &mut dyn FnMut(&FitProgress),
) -> Result<FittedVolume> {
    // The start is the final grid: no growth, whatever the config's start size says.
    let config = FitConfig {
        start_size: config.size,
        ..config.clone()
    };
    config.validate()?;
    let s = config.size;
    if initial.dims() != [CHANNELS, s, s, s] {
        return Err(invalid(
            "initial volume",
            format!(
                "expected raw values of shape [{CHANNELS}, {s}, {s}, {s}] (the fit's size), got {:?}",
                initial.dims()
            ),
        ));
    }
    let raw: Vec<f32> = initial
        .flatten_all()?
        .to_dtype(candle_core::DType::F32)?
        .to_vec1()?;
    if let Some(bad) = raw.iter().position(|v| !v.is_finite()) {
        return Err(invalid(
            "initial volume",
            format!(
                "expected finite raw values, found {} at index {bad}",
                raw[bad]
            ),
        ));
    }
    let grid = FitGrid::from_raw(s, raw, config.activation).post_activated(config.post_activation);
    run_fit(dataset, training, &config, grid, observer)
}

/// The fit's loop from `grid` on: ray batches, losses, Adam steps, growth and occupancy.
fn run_fit(
    dataset: &Dataset,
    training: &[usize],
    config: &FitConfig,
    mut grid: FitGrid,
    observer: &mut dyn FnMut(&FitProgress),
) -> Result<FittedVolume> {
    let views = dataset.subset(training)?;
    let level = views.level(views.width(), views.height(), &Device::Cpu)?;
    let bank = RayBank::from_level(&level)?;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(config.seed);
    let render_config = config
        .render_config()
        .with_depth(config.use_depth && config.lambda_depth > 0.0)
        .with_opacity(config.lambda_opacity > 0.0);
    let start = Instant::now();
    let mut step = 0;
    let mut steps_at_size = 0;
    loop {
        let fraction = match config.budget {
            FitBudget::Steps(n) => step as f32 / n as f32,
            FitBudget::Seconds(s) => (start.elapsed().as_secs_f64() / s) as f32,
        };
        if fraction >= 1.0 {
            break;
        }
        let size = config.size_at(fraction);
        if size != grid.size() {
            grid.grow(size)?;
            steps_at_size = 0;
        }
        // The first refresh waits for the fit to have put matter where the views show it.
        if config.occupancy_every > 0
            && steps_at_size > 0
            && steps_at_size % config.occupancy_every == 0
            && fraction > 0.05
        {
            grid.refresh_live(config.occupancy_threshold, voxel_length(config.aabb, size))?;
        }
        let batch = bank.batch(&mut rng, config.rays_per_step)?;
        let rendered = Var::from_tensor(&Tensor::from_vec(
            grid.rendered(),
            (CHANNELS, size, size, size),
            &Device::Cpu,
        )?)?;
        let out = render(rendered.as_tensor(), &batch.rays, &render_config)?;
        let colour_mse = (&out.rgb - &batch.rgb)?.sqr()?.mean_all()?;
        let mut loss = (&colour_mse * f64::from(config.lambda_color))?;
        if let Some(depth) = &out.depth {
            // Holes in the dataset's depth (weight 0) are left out, as training leaves them.
            let depth_mse = ((depth - &batch.depth)?.sqr()? * &batch.depth_weight)?.mean_all()?;
            loss = (loss + (depth_mse * f64::from(config.lambda_depth))?)?;
        }
        if let Some(opacity) = &out.opacity {
            let opacity_mse = (opacity - &batch.opacity)?.sqr()?.mean_all()?;
            loss = (loss + (opacity_mse * f64::from(config.lambda_opacity))?)?;
        }
        let loss_value = loss.to_scalar::<f32>()?;
        if !loss_value.is_finite() {
            return Err(invalid(
                "fit",
                format!("the loss became {loss_value} at step {step}; lower the learning rate"),
            ));
        }
        let grads = loss.backward()?;
        let mut grad: Vec<f32> = match grads.get(&rendered) {
            Some(g) => g.flatten_all()?.to_vec1()?,
            None => vec![0.0; CHANNELS * size * size * size],
        };
        grid.raw_gradient(&mut grad, &config.regularisers);
        grid.adam_step(&grad, config.learning_rate_at(fraction));
        step += 1;
        steps_at_size += 1;
        observer(&FitProgress {
            step,
            fraction,
            size,
            batch_psnr: -10.0 * f64::from(colour_mse.to_scalar::<f32>()?).log10(),
            live_fraction: grid.live_fraction(),
        });
    }
    let size = grid.size();
    let volume_of = |values: Vec<f32>| -> Result<RadianceVolume> {
        let data = Tensor::from_vec(values, (CHANNELS, size, size, size), &Device::Cpu)?;
        Ok(RadianceVolume::new(data, config.aabb)?)
    };
    let volume = volume_of(grid.physical())?;
    let rendered = if config.post_activation {
        volume_of(grid.rendered())?
    } else {
        volume.clone()
    };
    Ok(FittedVolume {
        volume,
        rendered,
        live_fraction: grid.live_fraction(),
        steps: step,
        seconds: start.elapsed().as_secs_f64(),
        raw: Tensor::from_vec(grid.into_raw(), (CHANNELS, size, size, size), &Device::Cpu)?,
    })
}

/// The edge of a voxel of an `size^3` grid over `aabb` (the smallest of the three).
fn voxel_length(aabb: Aabb, size: usize) -> f32 {
    aabb.size().min_element() / size as f32
}

/// Renders `volume` from `cameras` (all of one size) with the fit's renderer: colour
/// `(V, 3, h, w)`. The volume is physical, or with [`FitConfig::post_activation`] holds raw
/// density in channel 0 (as [`FittedVolume::rendered`]).
pub fn render_views(
    volume: &RadianceVolume,
    cameras: &[Camera],
    config: &FitConfig,
) -> Result<Tensor> {
    let Some(first) = cameras.first() else {
        return Err(invalid("cameras", "need at least one camera"));
    };
    let (w, h) = (first.width, first.height);
    let cfg = config.render_config().with_aabb(volume.aabb());
    let mut views = Vec::with_capacity(cameras.len());
    for camera in cameras {
        if (camera.width, camera.height) != (w, h) {
            return Err(invalid("cameras", "all cameras must share a size"));
        }
        let out = render(volume.tensor(), &Rays::from_camera(camera), &cfg)?;
        views.push(out.rgb.reshape((h, w, 3))?.permute((2, 0, 1))?);
    }
    Ok(Tensor::stack(&views, 0)?)
}

/// The colour PSNR (dB) of `volume` (as [`render_views`] takes it) rendered from each view
/// `indices` of `dataset` against its image (composited on the config's background, as the
/// dataset was loaded).
pub fn view_psnr(
    volume: &RadianceVolume,
    dataset: &Dataset,
    indices: &[usize],
    config: &FitConfig,
) -> Result<Vec<f64>> {
    let views = dataset.subset(indices)?;
    let level = views.level(views.width(), views.height(), &Device::Cpu)?;
    let rendered = render_views(volume, &level.cameras, config)?;
    Ok(scene_metrics::psnr_per_view(&rendered, &level.images)?)
}

/// The types most users of this crate need, for `use volume_fit::prelude::*;`.
pub mod prelude {
    pub use crate::{fit_volume, FitBudget, FitConfig, FittedVolume};
}

/// The README's examples, compiled and run as doc tests.
#[cfg(doctest)]
#[doc = include_str!("../README.md")]
pub struct ReadmeDoctests;

//! Sampling new scenes from a trained pyramid: a physical radiance volume per scene, and
//! renderings through the upsampler from chosen cameras.

use std::time::Instant;

use candle_core::Tensor;
use glam::Vec3;
use radiance_volume::{Aabb, Activation, RadianceVolume, Resampled};
use volrender::{Camera, DensityInterpolation, RenderConfig, PAPER_FOV_DEG, PAPER_RADIUS};

use crate::error::Result;
use crate::model::SinGrav;
use crate::render::{ViewMaps, ViewRenderer};
use rgbd_dataset::Dataset;
use volume_fit::{view_psnr, FitConfig};

/// One generated scene.
pub struct Sample {
    /// The scene as a physical volume over `[-1, 1]^3` (sigma, r, g, b).
    pub volume: RadianceVolume,
    /// The raw volume `(1, 4, s, s, s)` it was activated from (detached), for other
    /// activations of it such as [`SinGrav::to_physical_upsampled`].
    pub raw: Tensor,
    /// Its renderings `(V, 3, H, W)` at the final resolution (through G_N when it is trained).
    pub views: Tensor,
    /// Seconds to generate the volume (the 3D pyramid and the activation; no rendering).
    pub generation_seconds: f64,
}

/// The most rays one renderer call takes (and so the most pixels, doubled per side, one
/// upsampler call takes) when a model renders many views ([`SinGrav::render_raw`],
/// [`SinGrav::render_maps`]): the upsampler's activations and the renderer's buffers grow with
/// the views of a call: an `hd` sample's 39 views (3 shown, a 36-frame turntable) at 320^2
/// would otherwise go through the upsampler's 3x3 convolutions at once.
pub const RAYS_PER_CALL: usize = 1 << 16;

/// Splits `cameras` into consecutive runs of at most [`RAYS_PER_CALL`] rays, at least one camera
/// each: the views of one renderer and upsampler call.
///
/// ```
/// let cams = singrav::sample::showcase_cameras(7, 160)?;
/// let runs: Vec<usize> = singrav::sample::view_chunks(&cams).map(|c| c.len()).collect();
/// assert_eq!(runs, vec![2, 2, 2, 1]); // 160^2 rays per view, 2^16 per call
/// # Ok::<(), singrav::Error>(())
/// ```
pub fn view_chunks(cameras: &[Camera]) -> impl Iterator<Item = &[Camera]> {
    let rays = cameras.first().map_or(1, |c| c.width * c.height).max(1);
    cameras.chunks((RAYS_PER_CALL / rays).max(1))
}

/// `count` cameras on the paper's radius at 35 degrees elevation, evenly spaced in azimuth,
/// looking at the centre: fixed views for comparing samples, for a configuration without a
/// model (its sizes only). With a model, take [`SinGrav::showcase_cameras`], the one that
/// frames a scene of any [extent](SinGrav::set_extent).
///
/// ```
/// let cams = singrav::sample::showcase_cameras(3, 32)?;
/// assert_eq!(cams.len(), 3);
/// assert!((cams[0].position().length() - volrender::PAPER_RADIUS).abs() < 1e-5);
/// # Ok::<(), singrav::Error>(())
/// ```
pub fn showcase_cameras(count: usize, size: usize) -> Result<Vec<Camera>> {
    showcase_cameras_at(count, size, PAPER_RADIUS)
}

/// [`showcase_cameras`] at `radius` from the centre.
fn showcase_cameras_at(count: usize, size: usize, radius: f32) -> Result<Vec<Camera>> {
    let elevation = 35f32.to_radians();
    (0..count)
        .map(|i| {
            let azimuth = std::f32::consts::TAU * (i as f32 + 0.125) / count as f32;
            let eye = radius
                * Vec3::new(
                    elevation.cos() * azimuth.cos(),
                    elevation.cos() * azimuth.sin(),
                    elevation.sin(),
                );
            Ok(Camera::look_at(
                eye,
                Vec3::ZERO,
                Vec3::Z,
                size,
                size,
                PAPER_FOV_DEG.to_radians(),
            )?)
        })
        .collect()
}

impl SinGrav {
    /// Generates one scene with noise from `rng` and renders it from `cameras` (sized to the
    /// last 3D scale's rendering; the upsampler doubles them when trained).
    pub fn sample(&self, rng: &mut impl rand::Rng, cameras: &[Camera]) -> Result<Sample> {
        self.sample_varying_from(rng, cameras, 1)
    }

    /// [`SinGrav::sample`] with the scales below `vary_from` kept at the reconstruction's
    /// noise ([`SinGrav::draw_noise_from`]): V*'s layout with new finer structure. With the
    /// same `rng`, scene i differs from [`SinGrav::sample`]'s scene i only below `vary_from`.
    ///
    /// ```no_run
    /// use rand::SeedableRng;
    /// # let device = candle_core::Device::Cpu;
    /// let (model, _) = singrav::SinGrav::load("runs/stones".as_ref(), &device)?;
    /// let cameras = singrav::sample::showcase_cameras(3, model.render_size())?;
    /// let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
    /// let same_layout = model.sample_varying_from(&mut rng, &cameras, 2)?;
    /// # Ok::<(), singrav::Error>(())
    /// ```
    pub fn sample_varying_from(
        &self,
        rng: &mut impl rand::Rng,
        cameras: &[Camera],
        vary_from: usize,
    ) -> Result<Sample> {
        self.sample_with(|| self.generate_random_from(rng, vary_from), cameras)
    }

    /// The fixed-noise reconstruction V* ([`SinGrav::reconstruct`]) as a [`Sample`]: the scene
    /// training fits to the dataset, rendered from `cameras` like any sample.
    ///
    /// ```no_run
    /// # let device = candle_core::Device::Cpu;
    /// let (model, _) = singrav::SinGrav::load("runs/stones".as_ref(), &device)?;
    /// let cameras = singrav::sample::showcase_cameras(3, model.render_size())?;
    /// let v_star = model.reconstruction_sample(&cameras)?;
    /// println!("V* is {:?}", v_star.volume.dims());
    /// # Ok::<(), singrav::Error>(())
    /// ```
    pub fn reconstruction_sample(&self, cameras: &[Camera]) -> Result<Sample> {
        self.sample_with(|| self.reconstruct(), cameras)
    }

    /// Times `generate` (a raw volume of the finest 3D scale) and its activation, then renders.
    fn sample_with(
        &self,
        generate: impl FnOnce() -> Result<Tensor>,
        cameras: &[Camera],
    ) -> Result<Sample> {
        let started = Instant::now();
        let raw = generate()?;
        let volume = self.to_physical(&raw)?;
        let generation_seconds = started.elapsed().as_secs_f64();
        Ok(Sample {
            volume,
            views: self.render_raw(&raw, cameras)?,
            raw,
            generation_seconds,
        })
    }

    /// A random raw volume `(1, 4, s, s, s)` of the finest 3D scale built, from noise drawn
    /// from `rng` (detached; what [`SinGrav::sample`] activates and renders).
    pub fn generate_random(&self, rng: &mut impl rand::Rng) -> Result<Tensor> {
        self.generate_random_from(rng, 1)
    }

    /// [`SinGrav::generate_random`] with the scales below `vary_from` at the reconstruction's
    /// noise ([`SinGrav::draw_noise_from`]).
    pub fn generate_random_from(
        &self,
        rng: &mut impl rand::Rng,
        vary_from: usize,
    ) -> Result<Tensor> {
        let noise = self.draw_noise_from(self.volume_scales(), vary_from, rng)?;
        Ok(self.generate(&noise)?.detach())
    }

    /// The physical volume of a raw volume `(1, 4, s, s, s)`, through the configuration's
    /// activation, in the scene's coordinates: over `[-1, 1]^3` (or [`SinGrav::model_box`] at
    /// another [extent](SinGrav::set_extent)), or when the run was trained
    /// with [`RunPolicy::bounds`](crate::config::RunPolicy::bounds) over their
    /// [`cube`](rgbd_dataset::SceneBounds::cube) (scaled alike) with density divided by its half
    /// side (the same opacity along the longer rays).
    pub fn to_physical(&self, raw: &Tensor) -> Result<RadianceVolume> {
        let volume = self.config().activation().apply(&raw.squeeze(0)?)?;
        let (cube, half_side) = self.scene_cube();
        if half_side == 1.0 {
            return Ok(RadianceVolume::new(volume, cube)?);
        }
        let density = (volume.narrow(0, 0, 1)? / f64::from(half_side))?;
        let rest = volume.narrow(0, 1, volume.dim(0)? - 1)?;
        let volume = Tensor::cat(&[&density, &rest], 0)?;
        Ok(RadianceVolume::new(volume, cube)?)
    }

    /// The model's box ([`SinGrav::model_box`]) in the scene's coordinates and the half side of
    /// the learned cube there: the box itself and 1, or with
    /// [`RunPolicy::bounds`](crate::config::RunPolicy::bounds) the box placed in their cube.
    fn scene_cube(&self) -> (Aabb, f32) {
        let model_box = self.model_box();
        self.config().run.bounds.map_or((model_box, 1.0), |bounds| {
            let (centre, half) = (bounds.cube().center(), bounds.half_side());
            let scene_box = Aabb {
                min: centre + model_box.min * half,
                max: centre + model_box.max * half,
            };
            (scene_box, half)
        })
    }

    /// A raw volume `(1, 4, s, s, s)` as a renderer outside the model takes it, in the scene's
    /// coordinates, with the density rule to render it by: [`SinGrav::to_physical`] and
    /// physical density; or, for a run trained with
    /// [`Rendering::post_activation`](crate::config::Rendering::post_activation), the same with raw
    /// density in channel 0 and the post-activation that renders it as the model does (its
    /// scale divided by the bounds' half side, as `to_physical` divides density).
    ///
    /// ```
    /// use candle_core::{DType, Device, Tensor};
    /// use rand::SeedableRng;
    /// let config = singrav::TrainConfig::preset("micro")?.with(|c| c.rendering.post_activation = true);
    /// let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0);
    /// let model = singrav::SinGrav::new(&config, &Device::Cpu, &mut rng)?;
    /// let raw = (Tensor::ones((1, 4, 3, 3, 3), DType::F32, &Device::Cpu)? * -2.0)?;
    /// let (volume, density) = model.to_rendered(&raw)?;
    /// assert_eq!(density.post_activation(), Some([config.rendering.density_scale, config.rendering.density_shift]));
    /// // Density stays raw (volrender activates it per sample), colour is physical.
    /// let values: Vec<f32> = volume.tensor().flatten_all()?.to_vec1()?;
    /// assert_eq!((values[0], values[27]), (-2.0, 1.0 / (1.0 + 2f32.exp())));
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    pub fn to_rendered(&self, raw: &Tensor) -> Result<(RadianceVolume, DensityInterpolation)> {
        let config = self.config();
        if !config.rendering.post_activation {
            return Ok((self.to_physical(raw)?, DensityInterpolation::Physical));
        }
        let volume = config.activation().apply_colour(&raw.squeeze(0)?)?;
        let (aabb, half_side) = self.scene_cube();
        let density = DensityInterpolation::PostActivated {
            scale: config.rendering.density_scale / half_side,
            shift: config.rendering.density_shift,
        };
        Ok((RadianceVolume::new(volume, aabb)?, density))
    }

    /// The mean colour PSNR (dB) of a raw volume `(1, 4, s, s, s)` rendered by its density rule
    /// ([`SinGrav::to_rendered`], in the scene's coordinates) from every view `frames` of
    /// `dataset` (in the scene's coordinates too) at the dataset's resolution, as `volgen fit`
    /// reports its volumes (the fit's renderer and sampling) on the model's background: what
    /// `volgen eval` reports as V*'s `volume_psnr`, comparable with a direct fit's PSNR.
    ///
    /// ```no_run
    /// # let device = candle_core::Device::Cpu;
    /// let (model, _) = singrav::SinGrav::load("runs/stones".as_ref(), &device)?;
    /// let data = rgbd_dataset::Dataset::load("data/stones".as_ref(), model.config().rendering.background)?;
    /// let all: Vec<usize> = (0..data.len()).collect();
    /// println!("V*'s volume: {:.2} dB", model.volume_psnr(&model.reconstruct()?, &data, &all)?);
    /// # Ok::<(), singrav::Error>(())
    /// ```
    pub fn volume_psnr(&self, raw: &Tensor, dataset: &Dataset, frames: &[usize]) -> Result<f64> {
        let (volume, density) = self.to_rendered(raw)?;
        let defaults = FitConfig::default();
        let activation = match density.post_activation() {
            Some([scale, shift]) => Activation::default()
                .with_density_scale(scale)
                .with_density_shift(shift),
            None => defaults.activation,
        };
        let config = FitConfig {
            background: self.config().rendering.background,
            post_activation: density.post_activation().is_some(),
            activation,
            ..defaults
        };
        let per_view = view_psnr(&volume, dataset, frames, &config)?;
        Ok(per_view.iter().sum::<f64>() / per_view.len().max(1) as f64)
    }

    /// The physical volume of a raw volume `(1, 4, s, s, s)` on a grid `factor` (odd) times
    /// finer per axis, for renderers that interpolate physical density (Blender, OpenVDB
    /// tools, volrender's `DensityInterpolation::Physical`): every fine voxel holds what the
    /// model's own renderer computes at its centre ([`crate::export::physical_upsampled`] of
    /// [`SinGrav::to_rendered`]). For a run trained with
    /// [`Rendering::post_activation`](crate::config::Rendering::post_activation) the edges between
    /// its voxels come back; other runs' volumes render as at 1. `factor` 1 is
    /// [`SinGrav::to_physical`] bit for bit; even factors are refused.
    ///
    /// ```
    /// use candle_core::{DType, Device, Tensor};
    /// use rand::SeedableRng;
    /// let config = singrav::TrainConfig::preset("micro")?;
    /// let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0);
    /// let model = singrav::SinGrav::new(&config, &Device::Cpu, &mut rng)?;
    /// let raw = Tensor::zeros((1, 4, 3, 3, 3), DType::F32, &Device::Cpu)?;
    /// let fine = model.to_physical_upsampled(&raw, 3)?;
    /// assert_eq!(fine.dims(), radiance_volume::GridDims::cube(9));
    /// assert!(model.to_physical_upsampled(&raw, 2).is_err());
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    pub fn to_physical_upsampled(&self, raw: &Tensor, factor: usize) -> Result<RadianceVolume> {
        Ok(self.physical_source(raw, factor)?.to_volume()?)
    }

    /// [`SinGrav::to_physical_upsampled`] computed block by block when read, for the writers
    /// that stream a volume (`radiance_volume::io::write_safetensors`, `VdbWriter::new`, ...):
    /// at `factor` 3 an `hd` scene's 378^3 volume (0.9 GB) is never held whole.
    ///
    /// ```
    /// use candle_core::{DType, Device, Tensor};
    /// use radiance_volume::VolumeSource;
    /// use rand::SeedableRng;
    /// let config = singrav::TrainConfig::preset("micro")?;
    /// let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0);
    /// let model = singrav::SinGrav::new(&config, &Device::Cpu, &mut rng)?;
    /// let raw = Tensor::zeros((1, 4, 3, 3, 3), DType::F32, &Device::Cpu)?;
    /// let fine = model.physical_source(&raw, 5)?;
    /// assert_eq!(fine.dims(), radiance_volume::GridDims::cube(15));
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    pub fn physical_source(&self, raw: &Tensor, factor: usize) -> Result<Resampled> {
        if factor == 1 {
            let volume = self.to_physical(raw)?;
            let dims = volume.dims();
            return Ok(Resampled::new(volume, dims)?);
        }
        let (rendered, density) = self.to_rendered(raw)?;
        crate::export::physical_upsampled_source(&rendered, density, factor)
    }

    /// Renderings `(V, 3, H, W)` of a raw volume of the finest 3D scale from `cameras` (sized
    /// [`SinGrav::render_size`]), doubled by the upsampler G_N when it is trained.
    pub fn render_raw(&self, raw: &Tensor, cameras: &[Camera]) -> Result<Tensor> {
        let renderer = self.final_renderer();
        let views = view_chunks(cameras)
            .map(|chunk| {
                let refs: Vec<&Camera> = chunk.iter().collect();
                self.finish_views(renderer.render(raw, &refs)?.0)
            })
            .collect::<Result<Vec<_>>>()?;
        Ok(Tensor::cat(&views, 0)?)
    }

    /// Like [`SinGrav::render_raw`], with the expected depth in world units and the opacity of
    /// the 3D rendering: colour `(V, 3, H, W)` at the final size (through G_N when trained),
    /// depth and opacity `(V, 1, h, w)` at [`SinGrav::render_size`] (G_N makes colour only).
    ///
    /// ```no_run
    /// # let device = candle_core::Device::Cpu;
    /// let (model, _) = singrav::SinGrav::load("runs/stones".as_ref(), &device)?;
    /// let cameras = singrav::sample::showcase_cameras(2, model.render_size())?;
    /// let maps = model.render_maps(&model.reconstruct()?, &cameras)?;
    /// let size = model.render_size();
    /// assert_eq!(maps.opacity.dims(), &[2, 1, size, size]);
    /// # Ok::<(), singrav::Error>(())
    /// ```
    pub fn render_maps(&self, raw: &Tensor, cameras: &[Camera]) -> Result<ViewMaps> {
        let renderer = self.final_renderer();
        let chunks = view_chunks(cameras)
            .map(|chunk| {
                let refs: Vec<&Camera> = chunk.iter().collect();
                let maps = renderer.render_maps(raw, &refs)?;
                Ok(ViewMaps {
                    rgb: self.finish_views(maps.rgb)?,
                    ..maps
                })
            })
            .collect::<Result<Vec<_>>>()?;
        let join = |part: fn(&ViewMaps) -> &Tensor| -> Result<Tensor> {
            Ok(Tensor::cat(
                &chunks.iter().map(part).collect::<Vec<_>>(),
                0,
            )?)
        };
        Ok(ViewMaps {
            rgb: join(|m| &m.rgb)?,
            depth: join(|m| &m.depth)?,
            opacity: join(|m| &m.opacity)?,
        })
    }

    /// The fixed-noise reconstruction V*: the raw volume `(1, 4, s, s, s)` of the finest 3D
    /// scale built from the reconstruction noise ({z*_1, 0, ..., 0}, or with optimised finer
    /// noise {z*_1, z*_2, ...}; detached), the volume training fits to the dataset's views,
    /// plus the detail of training's final fit to the views when it ran
    /// ([`SinGrav::reconstruction_detail`]).
    ///
    /// ```no_run
    /// # let device = candle_core::Device::Cpu;
    /// let (model, _) = singrav::SinGrav::load("runs/stones".as_ref(), &device)?;
    /// let v_star = model.reconstruct()?;
    /// let volume = model.to_physical(&v_star)?;
    /// # Ok::<(), singrav::Error>(())
    /// ```
    pub fn reconstruct(&self) -> Result<Tensor> {
        self.check_learned_size("the reconstruction V*")?;
        let noise = self.reconstruction_noise(self.volume_scales())?;
        let volume = self.generate(&noise)?.detach();
        match self.reconstruction_detail() {
            Some(detail) => Ok((volume + detail)?),
            None => Ok(volume),
        }
    }

    /// The settings [`SinGrav::render_raw`] renders scenes with before the upsampler: the
    /// finest 3D scale's uniform samples per ray (grown with the box at another
    /// [extent](SinGrav::set_extent)), the background and the density rule, over
    /// [`SinGrav::model_box`] in the model's units. A renderer outside the model (a viewer)
    /// takes the samples and background from here and the volume and density rule from
    /// [`SinGrav::to_rendered`], which are in the scene's coordinates.
    ///
    /// ```
    /// use rand::SeedableRng;
    /// let config = singrav::TrainConfig::preset("micro")?;
    /// let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0);
    /// let mut model = singrav::SinGrav::new(&config, &candle_core::Device::Cpu, &mut rng)?;
    /// model.push_generator(1.0, &mut rng)?;
    /// let settings = model.render_config();
    /// assert_eq!(settings.sampler, volrender::Sampler::Uniform { samples: config.pyramid.samples[0] });
    /// assert_eq!(settings.background, Some(config.rendering.background));
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    pub fn render_config(&self) -> RenderConfig {
        *self.final_renderer().render_config()
    }

    /// The renderer of the finest 3D scale, depth in world units.
    fn final_renderer(&self) -> ViewRenderer {
        let last = self.volume_scales();
        ViewRenderer::new(
            self.config(),
            self.config().pyramid.samples[last - 1],
            1.0,
            false,
        )
        .over(self.model_box())
    }

    /// Colour renderings of the 3D pyramid as the model outputs them: doubled by G_N when it
    /// is trained, clamped to [0, 1], detached: G_N's weights are variables, so its output
    /// would otherwise hold every activation of its pass for a backward that never comes
    /// (about 0.4 GB per scene of four 320^2 views, which `volgen eval`'s 32 scenes kept).
    fn finish_views(&self, coarse: Tensor) -> Result<Tensor> {
        if self.has_upsampler() {
            Ok(self.upsample_images(&coarse)?.clamp(0f32, 1f32)?.detach())
        } else {
            Ok(coarse)
        }
    }

    /// [`showcase_cameras`] for this model's scenes: at the learned size the paper's radius and
    /// [`SinGrav::render_size`]; at a larger [extent](SinGrav::set_extent) both times the
    /// model box's largest half side, so the whole scene is in view at the learned pixel size.
    ///
    /// ```no_run
    /// # let device = candle_core::Device::Cpu;
    /// let (mut model, _) = singrav::SinGrav::load("runs/stones".as_ref(), &device)?;
    /// model.set_extent("2,2,1".parse()?, csg_embed::Outside::Mirror)?;
    /// let cameras = model.showcase_cameras(3)?;
    /// assert_eq!(cameras[0].width, 2 * model.render_size());
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    pub fn showcase_cameras(&self, count: usize) -> Result<Vec<Camera>> {
        let scale = self.model_box().max.max_element().max(1.0);
        let size = (self.render_size() as f32 * scale).round() as usize;
        showcase_cameras_at(count, size, PAPER_RADIUS * scale)
    }

    /// The rendering size the 3D pyramid produces (cameras for [`SinGrav::sample`] use it).
    pub fn render_size(&self) -> usize {
        self.config().pyramid.image_sizes[self.volume_scales() - 1]
    }
}

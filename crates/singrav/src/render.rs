//! Rendering raw generated volumes into image tensors for the critics and the losses.

use candle_core::Tensor;
use radiance_volume::{Aabb, Activation};
use volrender::{render, Camera, DensityInterpolation, Rays, RenderConfig, Sampler};

use crate::config::TrainConfig;
use crate::error::{invalid, Result};

/// Renders raw `(1, 4, s, s, s)` volumes (activation included) to `(V, 3, h, w)` colour and
/// `(V, 1, h, w)` normalised depth, differentiably.
#[derive(Debug, Clone)]
pub struct ViewRenderer {
    activation: Activation,
    config: RenderConfig,
    depth_norm: f32,
}

impl ViewRenderer {
    /// The renderer of training runs with `config`: `samples` uniform samples per ray, the
    /// configured background and density rule, and depth divided by
    /// `depth_norm` (so it is about 1 at the far side of the box) when `with_depth`.
    pub fn new(config: &TrainConfig, samples: usize, depth_norm: f32, with_depth: bool) -> Self {
        let render = RenderConfig::default()
            .with_sampler(Sampler::Uniform { samples })
            .with_background(config.rendering.background)
            .with_depth(with_depth)
            .with_density(config.density_interpolation());
        Self {
            activation: config.activation(),
            config: render,
            depth_norm,
        }
    }

    /// Renders volumes over `aabb` (in the model's units) instead of `[-1, 1]^3`: scenes
    /// generated at another [extent](crate::SinGrav::set_extent). The samples per ray grow with
    /// the box's diagonal, so along the longest rays they stay as far apart as in the learned
    /// box.
    pub fn over(mut self, aabb: Aabb) -> Self {
        if let Sampler::Uniform { samples } = self.config.sampler {
            let longest = aabb.size().length() / Aabb::CUBE.size().length();
            let samples = (samples as f32 * longest.max(1.0)).ceil() as usize;
            self.config = self.config.with_sampler(Sampler::Uniform { samples });
        }
        self.config.aabb = aabb;
        self
    }

    /// The volume renderer's settings: sampler, background, density rule, box.
    pub fn render_config(&self) -> &RenderConfig {
        &self.config
    }

    /// Also renders opacity (when `with_opacity`): [`ViewRenderer::render_joined`] then appends
    /// it as the critics' last channel and [`ViewRenderer::render_all`] returns it.
    pub fn with_opacity(mut self, with_opacity: bool) -> Self {
        self.config = self.config.with_opacity(with_opacity);
        self
    }

    /// Renders `raw` from every camera (all of one size) in one pass of the render op.
    pub fn render(&self, raw: &Tensor, cameras: &[&Camera]) -> Result<(Tensor, Option<Tensor>)> {
        let maps = self.render_with(raw, cameras, self.config)?;
        Ok((maps.rgb, maps.depth))
    }

    /// Renders `raw` from every camera with every output this renderer was configured for:
    /// colour, and depth and opacity when asked for.
    pub fn render_all(&self, raw: &Tensor, cameras: &[&Camera]) -> Result<OptionalMaps> {
        self.render_with(raw, cameras, self.config)
    }

    /// Renders `raw` from every camera with colour `(V, 3, h, w)`, depth `(V, 1, h, w)` (divided
    /// by the depth normaliser) and opacity `(V, 1, h, w)`, whatever `with_depth` said: what the
    /// metrics compare with a dataset's images, depth maps and alpha.
    pub fn render_maps(&self, raw: &Tensor, cameras: &[&Camera]) -> Result<ViewMaps> {
        let config = self.config.with_depth(true).with_opacity(true);
        let maps = self.render_with(raw, cameras, config)?;
        let missing = || invalid("renderer", "returned no depth or opacity");
        Ok(ViewMaps {
            rgb: maps.rgb,
            depth: maps.depth.ok_or_else(missing)?,
            opacity: maps.opacity.ok_or_else(missing)?,
        })
    }

    /// One pass of the renderer with `config`'s outputs, reshaped to `(V, C, h, w)` maps on
    /// the volume's device.
    fn render_with(
        &self,
        raw: &Tensor,
        cameras: &[&Camera],
        config: RenderConfig,
    ) -> Result<OptionalMaps> {
        let Some(first) = cameras.first() else {
            return Err(invalid("cameras", "need at least one camera"));
        };
        let (w, h) = (first.width, first.height);
        if cameras.iter().any(|c| (c.width, c.height) != (w, h)) {
            return Err(invalid(
                "cameras",
                "all cameras of one call must share a size",
            ));
        }
        let mut origins = Vec::with_capacity(cameras.len() * w * h);
        let mut dirs = Vec::with_capacity(cameras.len() * w * h);
        for camera in cameras {
            let rays = Rays::from_camera(camera);
            origins.extend_from_slice(rays.origins());
            dirs.extend_from_slice(rays.dirs());
        }
        let out = self.render_rays(raw, &Rays::new(origins, dirs)?, config)?;
        let views = cameras.len();
        let rgb = out
            .rgb
            .reshape((views, h, w, 3))?
            .permute((0, 3, 1, 2))?
            .contiguous()?;
        let plane = |t: Tensor| -> Result<Tensor> { Ok(t.reshape((views, 1, h, w))?) };
        Ok(OptionalMaps {
            rgb,
            depth: out.depth.map(plane).transpose()?,
            opacity: out.opacity.map(plane).transpose()?,
        })
    }

    /// Renders `raw` along the rays through `pixels`, each `(camera, row-major pixel index)`,
    /// with every output this renderer was configured for: colour `(P, 3)`, and depth (divided
    /// by the depth normaliser) and opacity `(P, 1)` when asked for. A loss on a random set of
    /// pixels over many views costs what its pixels cost, not what whole views do.
    pub fn render_pixels(&self, raw: &Tensor, pixels: &[(&Camera, usize)]) -> Result<OptionalMaps> {
        if pixels.is_empty() {
            return Err(invalid("pixels", "need at least one pixel"));
        }
        let (origins, dirs) = pixels
            .iter()
            .map(|&(camera, pixel)| {
                let (row, col) = (pixel / camera.width, pixel % camera.width);
                let (origin, dir) = camera.ray(row as f32 + 0.5, col as f32 + 0.5);
                (origin.to_array(), dir.to_array())
            })
            .unzip();
        let out = self.render_rays(raw, &Rays::new(origins, dirs)?, self.config)?;
        let column = |t: Tensor| -> Result<Tensor> { Ok(t.unsqueeze(1)?) };
        Ok(OptionalMaps {
            rgb: out.rgb,
            depth: out.depth.map(column).transpose()?,
            opacity: out.opacity.map(column).transpose()?,
        })
    }

    /// One pass of the render op along `rays` with `config`'s outputs (depth divided by the
    /// depth normaliser). On the CPU the fused kernel renders; on another device volrender's
    /// portable path (candle ops), so the volume stays where it is. A post-activating renderer
    /// takes raw density and activates it per sample.
    fn render_rays(
        &self,
        raw: &Tensor,
        rays: &Rays,
        config: RenderConfig,
    ) -> Result<volrender::RenderOutput> {
        let raw = raw.squeeze(0)?;
        let physical = match config.density {
            DensityInterpolation::Physical => self.activation.apply(&raw)?,
            DensityInterpolation::PostActivated { .. } => self.activation.apply_colour(&raw)?,
        };
        let mut out = render(&physical, rays, &config)?;
        out.depth = out
            .depth
            .map(|d| d / f64::from(self.depth_norm))
            .transpose()?;
        Ok(out)
    }

    /// Renders and joins colour, depth and opacity into the critics' `(V, C, h, w)` input:
    /// colour, then depth and opacity where the renderer makes them (`C` is 3 to 5).
    pub fn render_joined(&self, raw: &Tensor, cameras: &[&Camera]) -> Result<Tensor> {
        let maps = self.render_all(raw, cameras)?;
        let channels: Vec<&Tensor> = std::iter::once(&maps.rgb)
            .chain(maps.depth.as_ref())
            .chain(maps.opacity.as_ref())
            .collect();
        Ok(Tensor::cat(&channels, 1)?)
    }
}

/// Colour, depth and opacity of renderings, each `(V, C, h, w)`, as
/// [`ViewRenderer::render_maps`] and [`crate::SinGrav::render_maps`] return them.
#[derive(Debug, Clone)]
pub struct ViewMaps {
    /// Colour `(V, 3, h, w)`, composited on the background.
    pub rgb: Tensor,
    /// Expected depth `(V, 1, h, w)` (0 where nothing is hit), divided by the renderer's depth
    /// normaliser (world units when it is 1).
    pub depth: Tensor,
    /// Opacity `(V, 1, h, w)` in [0, 1].
    pub opacity: Tensor,
}

/// [`ViewMaps`] with the outputs a render configuration may leave out: of whole views
/// (`(V, C, h, w)`), or of single pixels (`(P, C)`, [`ViewRenderer::render_pixels`]).
#[derive(Debug, Clone)]
pub struct OptionalMaps {
    /// Colour `(V, 3, h, w)` or `(P, 3)`, composited on the background.
    pub rgb: Tensor,
    /// Normalised expected depth `(V, 1, h, w)` or `(P, 1)`, when rendered.
    pub depth: Option<Tensor>,
    /// Opacity `(V, 1, h, w)` or `(P, 1)`, when rendered.
    pub opacity: Option<Tensor>,
}

#[cfg(test)]
mod tests {
    use candle_core::{Device, Tensor, Var};
    use glam::Vec3;
    use volrender::Camera;

    use super::ViewRenderer;
    use crate::config::TrainConfig;

    /// Rendering single pixels gives exactly those pixels of the whole views, with their
    /// gradient: what the reconstruction loss on random pixels relies on.
    #[test]
    fn pixels_render_as_the_same_pixels_of_whole_views() {
        let device = Device::Cpu;
        let config = TrainConfig::preset("micro").unwrap();
        let renderer = ViewRenderer::new(&config, 24, 4.0, true).with_opacity(true);
        let cameras = [
            Camera::look_at(Vec3::new(0.3, 0.8, 3.0), Vec3::ZERO, Vec3::Y, 7, 7, 0.8).unwrap(),
            Camera::look_at(Vec3::new(-2.0, 1.0, 1.5), Vec3::ZERO, Vec3::Z, 7, 7, 0.8).unwrap(),
        ];
        let raw =
            Var::from_tensor(&Tensor::rand(-3f32, 3.0, (1, 4, 6, 6, 6), &device).unwrap()).unwrap();
        let views = renderer
            .render_all(raw.as_tensor(), &[&cameras[0], &cameras[1]])
            .unwrap();
        let chosen = [(1, 0), (0, 48), (1, 24), (0, 3)];
        let pixels: Vec<_> = chosen.iter().map(|&(v, p)| (&cameras[v], p)).collect();
        let single = renderer.render_pixels(raw.as_tensor(), &pixels).unwrap();
        let at = |maps: &Tensor, v: usize, p: usize| -> Vec<f32> {
            let channels = maps.dim(1).unwrap();
            (0..channels)
                .map(|c| {
                    maps.get(v)
                        .unwrap()
                        .get(c)
                        .unwrap()
                        .flatten_all()
                        .unwrap()
                        .to_vec1::<f32>()
                        .unwrap()[p]
                })
                .collect()
        };
        let depth = single.depth.as_ref().unwrap();
        let opacity = single.opacity.as_ref().unwrap();
        for (i, &(v, p)) in chosen.iter().enumerate() {
            let row = |t: &Tensor| t.get(i).unwrap().to_vec1::<f32>().unwrap();
            assert_eq!(row(&single.rgb), at(&views.rgb, v, p));
            assert_eq!(row(depth), at(views.depth.as_ref().unwrap(), v, p));
            assert_eq!(row(opacity), at(views.opacity.as_ref().unwrap(), v, p));
        }
        // A loss on those pixels of the whole views has the same gradient.
        let picked = |maps: &Tensor| -> Tensor {
            let columns: Vec<Tensor> = chosen
                .iter()
                .map(|&(v, p)| {
                    let (c, h, w) = maps.get(v).unwrap().dims3().unwrap();
                    maps.get(v)
                        .unwrap()
                        .reshape((c, h * w))
                        .unwrap()
                        .narrow(1, p, 1)
                        .unwrap()
                })
                .collect();
            Tensor::cat(&columns, 1).unwrap()
        };
        let whole = picked(&views.rgb).sqr().unwrap().sum_all().unwrap();
        let part = single.rgb.sqr().unwrap().sum_all().unwrap();
        let (g_whole, g_part) = (whole.backward().unwrap(), part.backward().unwrap());
        let grad = |g: &candle_core::backprop::GradStore| -> Vec<f32> {
            g.get(raw.as_tensor())
                .unwrap()
                .flatten_all()
                .unwrap()
                .to_vec1()
                .unwrap()
        };
        let (a, b) = (grad(&g_whole), grad(&g_part));
        for (x, y) in a.iter().zip(&b) {
            assert!((x - y).abs() <= 1e-6 * (1.0 + x.abs()), "{x} against {y}");
        }
        assert!(renderer.render_pixels(raw.as_tensor(), &[]).is_err());
    }
}

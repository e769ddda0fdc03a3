//! Training one 3D scale n < N: G_n against the depth-conditioned critic D_n, with the
//! reconstruction of the dataset views from the fixed noise.

use std::collections::HashMap;

use candle_core::{Tensor, D};
use radiance_volume::RadianceVolume;
use rand::Rng;

use rgbd_dataset::DatasetLevel;

use super::colour::{chroma_distribution_loss, colour_distribution_loss};
use super::critic::{Critic, VolumeCritic};
use super::fitted::{FittedTarget, VolumeSight};
use super::height_profile::height_profile_loss;
use super::losses::{LossTerm, StepLosses, StepMeans, StepTerms};
use super::sample_opacity::opacity_binary_loss;
use super::stage::{Stage, StageParts};
use crate::config::TrainConfig;
use crate::error::Result;
use crate::model::{named_vars, SinGrav};
use crate::optim::Adam;
use crate::render::ViewRenderer;

/// A loss on the samples' rendered opacity against the real views' alpha (both `(V, 1, h, w)`).
type OpacityLoss = fn(&Tensor, &Tensor) -> Result<Tensor>;

/// A loss on the samples' rendered colours against the real views' (both `(V, 3, h, w)`), with
/// random directions drawn from the generator.
type ColourLoss = fn(&Tensor, &Tensor, usize, &mut rand_chacha::ChaCha8Rng) -> Result<Tensor>;

/// One iteration's random draw: the noise of this scale and the volume of the frozen scales
/// below it. As in SinGAN, noise is drawn once per iteration: the critic steps see the same
/// fake (here from different views) and the generator steps refine the same draw.
struct Draw {
    noise: Tensor,
    frozen: Option<Tensor>,
}

/// The state of one 3D scale's training.
pub(super) struct VolumeScale<'a> {
    model: &'a SinGrav,
    config: &'a TrainConfig,
    /// The scale, 1-based.
    n: usize,
    level: DatasetLevel,
    /// Real critic inputs: colour and normalised depth `(V, 4, h, w)` (colour only without depth).
    real: Tensor,
    renderer: ViewRenderer,
    critic: Critic,
    opt: Adam,
    /// The optimiser of this scale's reconstruction noise z*_n, when the run optimises it.
    noise_opt: Option<Adam>,
    /// The reconstruction V*_{n-1} (raw) of the frozen scales below; `None` when scale 1
    /// trains.
    frozen_reconstruction: Option<Tensor>,
    /// This scale's reconstruction noise (z*_1, zeros, or the optimised z*_n).
    reconstruction_noise: Tensor,
    /// The fitted volume at this scale's size, when the run trains against one.
    fitted: Option<FittedTarget>,
    /// The 3D critic of volumes (runs with `losses.volume_critic > 0`), judging against
    /// `fitted`.
    volume_critic: Option<VolumeCritic>,
    /// Every training pixel's targets, when the reconstruction renders random pixels rather
    /// than whole views (fewer pixels per step than its views hold).
    pixel_targets: Option<PixelTargets>,
}

/// What a reconstruction's renderings are compared with: colour, alpha and, where depth is
/// supervised, normalised depth and its weights; each `(V, C, h, w)` for whole views or
/// `(P, C)` for pixels.
struct Targets {
    rgb: Tensor,
    alpha: Tensor,
    depth: Option<Tensor>,
    depth_mask: Option<Tensor>,
}

/// The targets of every pixel of every view, `(V h w, C)` (view, then row-major pixel), and how
/// many of them a step renders.
struct PixelTargets {
    all: Targets,
    per_step: usize,
}

impl PixelTargets {
    /// `per_step` pixels of `level`'s views with critic inputs `real` (colour, normalised depth
    /// when `with_depth`, ...).
    fn new(level: &DatasetLevel, real: &Tensor, with_depth: bool, per_step: usize) -> Result<Self> {
        let flat = |t: &Tensor| -> Result<Tensor> {
            let (v, c, h, w) = t.dims4()?;
            Ok(t.permute((0, 2, 3, 1))?
                .contiguous()?
                .reshape((v * h * w, c))?)
        };
        Ok(Self {
            all: Targets {
                rgb: flat(&level.images)?,
                alpha: flat(&level.opacity)?,
                depth: with_depth
                    .then(|| flat(&real.narrow(1, 3, 1)?))
                    .transpose()?,
                depth_mask: level.depth_mask.as_ref().map(flat).transpose()?,
            },
            per_step,
        })
    }

    /// Every training pixel.
    fn len(&self) -> Result<usize> {
        Ok(self.all.rgb.dim(0)?)
    }

    /// The targets of the pixels `chosen`.
    fn select(&self, chosen: &[usize]) -> Result<Targets> {
        let index: Vec<u32> = chosen.iter().map(|&i| i as u32).collect();
        let index = Tensor::from_vec(index, chosen.len(), self.all.rgb.device())?;
        let pick = |t: &Tensor| -> Result<Tensor> { Ok(t.index_select(&index, 0)?) };
        Ok(Targets {
            rgb: pick(&self.all.rgb)?,
            alpha: pick(&self.all.alpha)?,
            depth: self.all.depth.as_ref().map(pick).transpose()?,
            depth_mask: self.all.depth_mask.as_ref().map(pick).transpose()?,
        })
    }
}

/// `count` distinct views out of `views` (all of them when there are fewer), drawn from `rng`.
pub(super) fn pick_views(rng: &mut impl Rng, views: usize, count: usize) -> Vec<usize> {
    rand::seq::index::sample(rng, views, count.min(views)).into_vec()
}

/// The images of `views` from a `(V, ...)` tensor.
pub(super) fn select(images: &Tensor, views: &[usize]) -> Result<Tensor> {
    let index: Vec<u32> = views.iter().map(|&v| v as u32).collect();
    let index = Tensor::from_vec(index, views.len(), images.device())?;
    Ok(images.index_select(&index, 0)?)
}

/// Mean squared error of two equally shaped tensors.
pub(super) fn mse(a: &Tensor, b: &Tensor) -> Result<Tensor> {
    Ok((a - b)?.sqr()?.mean_all()?)
}

/// Mean squared error of two equally shaped tensors weighted by `mask` (same shape, >= 0):
/// pixels without known depth do not count; 0 when nothing counts.
fn masked_mse(a: &Tensor, b: &Tensor, mask: &Tensor) -> Result<Tensor> {
    let weighted = ((a - b)?.sqr()? * mask)?.sum_all()?;
    let count = mask.sum_all()?.maximum(1e-6)?;
    Ok((weighted / count)?)
}

impl<'a> VolumeScale<'a> {
    /// Sets up scale `n` (its generator already pushed onto `model`) on top of the frozen
    /// scales' fixed reconstruction.
    pub fn new(
        model: &'a SinGrav,
        n: usize,
        level: DatasetLevel,
        depth_norm: f32,
        previous_critic: Option<&HashMap<String, Tensor>>,
        rng: &mut impl Rng,
    ) -> Result<Self> {
        let config = model.config();
        let renderer = ViewRenderer::new(
            config,
            config.pyramid.samples[n - 1],
            depth_norm,
            config.ablations.use_depth,
        )
        .with_opacity(config.critics.opacity || config.losses.opacity > 0.0);
        let real = critic_input(config, &level, depth_norm)?;
        let in_channels = real.dim(1)?;
        let critic = Critic::new(config, in_channels, previous_critic, model.device(), rng)?;
        let vars = model
            .generator_vars(n)
            .ok_or_else(|| crate::error::invalid("scale", format!("generator {n} is not built")))?;
        let opt = Adam::new(
            named_vars(vars),
            config.schedule.learning_rate,
            config.schedule.betas,
        )?;
        let noise_opt = model
            .reconstruction_noise_var(n)
            .map(|z| {
                Adam::new(
                    vec![("z_star".into(), z.clone())],
                    config.noise.reconstruction_lr,
                    config.schedule.betas,
                )
            })
            .transpose()?;
        let mut frozen_noise = model.reconstruction_noise(n)?;
        let reconstruction_noise = frozen_noise
            .pop()
            .ok_or_else(|| crate::error::invalid("scale", format!("scale {n} has no noise")))?;
        let frozen_reconstruction = if frozen_noise.is_empty() {
            None
        } else {
            Some(model.generate(&frozen_noise)?.detach())
        };
        let view_pixels = level.images.dim(2)? * level.images.dim(3)?;
        let whole_views = config.views(n).reconstruction * view_pixels;
        let pixel_targets = config
            .schedule
            .reconstruction_pixels
            .filter(|&per_step| per_step < whole_views)
            .map(|per_step| PixelTargets::new(&level, &real, config.ablations.use_depth, per_step))
            .transpose()?;
        Ok(Self {
            model,
            config,
            n,
            level,
            real,
            renderer,
            critic,
            opt,
            noise_opt,
            frozen_reconstruction,
            reconstruction_noise,
            fitted: None,
            volume_critic: None,
            pixel_targets,
        })
    }

    /// Trains against `fitted` (resampled to this scale): the reconstruction is compared with
    /// it in 3D, weighted by the configuration's `losses.fitted`, and with a positive
    /// `losses.volume_critic` a 3D critic (seeded from `rng`, then copied from
    /// `previous_volume_critic`, the last scale's, where shapes agree) judges the generated
    /// volumes against it.
    pub fn with_fitted(
        mut self,
        fitted: Option<&RadianceVolume>,
        previous_volume_critic: Option<&HashMap<String, Tensor>>,
        rng: &mut impl Rng,
    ) -> Result<Self> {
        let size = self.config.pyramid.volume_sizes[self.n - 1];
        self.fitted = fitted
            .map(|volume| {
                let density = self.config.density_interpolation();
                FittedTarget::new(volume, size, density, self.model.device())
            })
            .transpose()?;
        let judged = self
            .config
            .critics
            .volume_until_scale
            .is_none_or(|last| self.n <= last);
        if self.config.losses.volume_critic > 0.0 && judged {
            if self.fitted.is_none() {
                return Err(crate::error::invalid(
                    "losses.volume_critic",
                    "the 3D critic judges against a fitted volume, and none was given",
                ));
            }
            self.volume_critic = Some(VolumeCritic::new(
                self.config,
                VolumeSight::of(&self.config.critics).channels(),
                previous_volume_critic,
                self.model.device(),
                rng,
            )?);
        }
        Ok(self)
    }

    /// Draws fresh noise at every scale and runs the frozen scales on it.
    fn draw(&self, rng: &mut impl Rng) -> Result<Draw> {
        let mut noise = self.model.draw_noise(self.n, rng)?;
        let own = noise
            .pop()
            .ok_or_else(|| crate::error::invalid("scale", "no 3D scale to generate"))?;
        let frozen = if noise.is_empty() {
            None
        } else {
            Some(self.model.generate(&noise)?.detach())
        };
        Ok(Draw { noise: own, frozen })
    }

    /// This scale's generator on `noise` on top of the volume `frozen` of the scales below it:
    /// differentiable in the generator.
    fn run_generator(&self, frozen: Option<&Tensor>, noise: &Tensor) -> Result<Tensor> {
        match frozen {
            None => self.model.coarsest(noise),
            Some(prev) => self.model.refine(self.n, noise, prev),
        }
    }

    /// The random volume of this scale for a draw, differentiable in the generator.
    fn fake_volume(&self, draw: &Draw) -> Result<Tensor> {
        self.run_generator(draw.frozen.as_ref(), &draw.noise)
    }

    /// The reconstruction V*_n from the reconstruction noise, differentiable in the generator
    /// (and in this scale's z*_n when it is optimised).
    fn reconstruction(&self) -> Result<Tensor> {
        self.run_generator(
            self.frozen_reconstruction.as_ref(),
            &self.reconstruction_noise,
        )
    }

    /// The critics' part of an iteration: the 3D critic's steps (runs with one) and the 2D
    /// critic's, each against this draw's volume.
    fn critic_steps(
        &mut self,
        draw: &Draw,
        rng: &mut rand_chacha::ChaCha8Rng,
        losses: &mut StepLosses,
    ) -> Result<()> {
        let fake_volume = self.fake_volume(draw)?.detach();
        if let (Some(critic), Some(fitted)) = (&mut self.volume_critic, &self.fitted) {
            let sight = VolumeSight::of(&self.config.critics);
            let real = fitted.features(sight)?;
            let fake = fitted.volume_features(&fake_volume, &self.config.activation(), sight)?;
            // One real volume and this iteration's one fake at every step.
            let (critic, penalty) =
                critic.steps_on(self.config, rng, |_| Ok((real.clone(), fake.clone())))?;
            losses.set(LossTerm::VolumeCritic, critic);
            losses.set(LossTerm::VolumePenalty, penalty);
        }
        let (renderer, cameras) = (&self.renderer, &self.level.cameras);
        let channels = self.real.dim(1)?;
        let batch = self.config.views(self.n).generated;
        let (critic, penalty) =
            self.critic
                .steps(self.config, batch, &self.real, rng, |views| {
                    let cams: Vec<_> = views.iter().map(|&v| &cameras[v]).collect();
                    critic_view(renderer, &fake_volume, &cams, channels)
                })?;
        losses.set(LossTerm::Critic, critic);
        losses.set(LossTerm::Penalty, penalty);
        Ok(())
    }

    /// A generator step's terms on a sample of this draw: the adversarial terms, then the
    /// distributions of its colours and of its rendered opacity against the real views'.
    fn sample_terms(
        &self,
        draw: &Draw,
        rng: &mut rand_chacha::ChaCha8Rng,
        terms: &mut StepTerms,
    ) -> Result<()> {
        let losses = &self.config.losses;
        let fake_views = pick_views(rng, self.views(), self.config.views(self.n).generated);
        let fake_volume = self.fake_volume(draw)?;
        if let (Some(critic), Some(fitted)) = (&self.volume_critic, &self.fitted) {
            let features = fitted.volume_features(
                &fake_volume,
                &self.config.activation(),
                VolumeSight::of(&self.config.critics),
            )?;
            let loss = (critic.generator_loss(&features)? * losses.volume_critic)?;
            terms.add(LossTerm::VolumeAdversarial, loss);
        }
        let fake = critic_view(
            &self.renderer,
            &fake_volume,
            &self.cameras(&fake_views),
            self.real.dim(1)?,
        )?;
        terms.add(LossTerm::Adversarial, self.critic.generator_loss(&fake)?);
        let colour_terms: [(LossTerm, f64, ColourLoss); 2] = [
            (
                LossTerm::ColourDistribution,
                losses.colour_distribution,
                colour_distribution_loss,
            ),
            (
                LossTerm::ChromaDistribution,
                losses.chroma_distribution,
                chroma_distribution_loss,
            ),
        ];
        if colour_terms.iter().any(|(_, weight, _)| *weight > 0.0) {
            let colour = fake.narrow(1, 0, 3)?;
            let real = select(&self.level.images, &fake_views)?;
            let grid = losses.colour_grid.unwrap_or(1);
            for (term, weight, loss) in colour_terms {
                if weight > 0.0 {
                    terms.add(term, (loss(&colour, &real, grid, rng)? * weight)?);
                }
            }
        }
        let opacity_terms: [(LossTerm, f64, OpacityLoss); 2] = [
            (
                LossTerm::HeightProfile,
                losses.height_profile,
                height_profile_loss,
            ),
            (
                LossTerm::OpacityBinary,
                losses.opacity_binary,
                |opacity, _| opacity_binary_loss(opacity),
            ),
        ];
        if opacity_terms.iter().any(|(_, weight, _)| *weight > 0.0) {
            // Validation keeps these weights at 0 unless the critics' views end with the
            // rendered opacity.
            let opacity = fake.narrow(1, fake.dim(1)? - 1, 1)?;
            let alpha = select(&self.level.opacity, &fake_views)?;
            for (term, weight, loss) in opacity_terms {
                if weight > 0.0 {
                    terms.add(term, (loss(&opacity, &alpha)? * weight)?);
                }
            }
        }
        Ok(())
    }

    /// A generator step's terms on the reconstruction V*_n: against the fitted volume (runs
    /// with one), then its renderings' opacity, colour and depth against the real views' (whole
    /// views, or random pixels over all of them where [`Schedule::reconstruction_pixels`]
    /// says so).
    ///
    /// [`Schedule::reconstruction_pixels`]: crate::config::Schedule::reconstruction_pixels
    fn reconstruction_terms(
        &self,
        rng: &mut rand_chacha::ChaCha8Rng,
        terms: &mut StepTerms,
    ) -> Result<()> {
        let losses = &self.config.losses;
        let rec_views = match self.pixel_targets {
            Some(_) => Vec::new(),
            None => pick_views(rng, self.views(), self.config.views(self.n).reconstruction),
        };
        let reconstruction = self.reconstruction()?;
        if let (Some(fitted), true) = (&self.fitted, losses.fitted > 0.0) {
            let loss = fitted.loss(&reconstruction, &self.config.activation())?;
            terms.add(LossTerm::Fitted, (loss * losses.fitted)?);
        }
        let (maps, real) = match &self.pixel_targets {
            Some(all) => {
                let chosen = rand::seq::index::sample(rng, all.len()?, all.per_step).into_vec();
                let pixels = self.level.cameras[0].width * self.level.cameras[0].height;
                let rays: Vec<_> = chosen
                    .iter()
                    .map(|&i| (&self.level.cameras[i / pixels], i % pixels))
                    .collect();
                let maps = self.renderer.render_pixels(&reconstruction, &rays)?;
                (maps, all.select(&chosen)?)
            }
            None => {
                let maps = self
                    .renderer
                    .render_all(&reconstruction, &self.cameras(&rec_views))?;
                (maps, self.view_targets(&rec_views)?)
            }
        };
        if let (Some(opacity), true) = (&maps.opacity, losses.opacity > 0.0) {
            terms.add(
                LossTerm::Opacity,
                (mse(opacity, &real.alpha)? * losses.opacity)?,
            );
        }
        terms.add(LossTerm::Rgb, (mse(&maps.rgb, &real.rgb)? * losses.rgb)?);
        if let (Some(depth), Some(real_depth)) = (maps.depth, &real.depth) {
            let error = match &real.depth_mask {
                None => mse(&depth, real_depth)?,
                Some(mask) => masked_mse(&depth, real_depth, mask)?,
            };
            terms.add(LossTerm::Depth, (error * losses.depth)?);
        }
        Ok(())
    }

    /// The reconstruction's targets from whole views.
    fn view_targets(&self, views: &[usize]) -> Result<Targets> {
        Ok(Targets {
            rgb: select(&self.level.images, views)?,
            alpha: select(&self.level.opacity, views)?,
            depth: self
                .config
                .ablations
                .use_depth
                .then(|| -> Result<Tensor> { Ok(select(&self.real, views)?.narrow(1, 3, 1)?) })
                .transpose()?,
            depth_mask: self
                .level
                .depth_mask
                .as_ref()
                .map(|mask| select(mask, views))
                .transpose()?,
        })
    }

    fn views(&self) -> usize {
        self.level.cameras.len()
    }

    fn cameras(&self, views: &[usize]) -> Vec<&volrender::Camera> {
        views.iter().map(|&v| &self.level.cameras[v]).collect()
    }
}

impl Stage for VolumeScale<'_> {
    fn iteration(
        &mut self,
        adversarial: bool,
        rng: &mut rand_chacha::ChaCha8Rng,
    ) -> Result<StepLosses> {
        let mut losses = StepLosses::default();
        let draw = if adversarial {
            Some(self.draw(rng)?)
        } else {
            None
        };
        if let Some(draw) = &draw {
            self.critic_steps(draw, rng, &mut losses)?;
        }
        let mut means = StepMeans::new();
        for _ in 0..self.config.schedule.g_steps {
            let mut terms = StepTerms::new();
            if let Some(draw) = &draw {
                self.sample_terms(draw, rng, &mut terms)?;
            }
            self.reconstruction_terms(rng, &mut terms)?;
            means.add(&terms)?;
            let grads = terms.total(self.model.device())?.backward()?;
            self.opt.step(&grads)?;
            if let Some(opt) = &mut self.noise_opt {
                opt.step(&grads)?;
            }
        }
        means.write_into(&mut losses);
        Ok(losses)
    }

    fn picture_rows(
        &self,
        rng: &mut rand_chacha::ChaCha8Rng,
        count: usize,
    ) -> Result<Vec<Vec<Tensor>>> {
        let camera = [&self.level.cameras[0]];
        let mut row = vec![
            self.level.images.get(0)?,
            self.renderer
                .render(&self.reconstruction()?.detach(), &camera)?
                .0
                .get(0)?,
        ];
        for _ in 0..count {
            let fake = self.fake_volume(&self.draw(rng)?)?.detach();
            row.push(self.renderer.render(&fake, &camera)?.0.get(0)?);
        }
        Ok(vec![row])
    }

    fn parts(&mut self) -> StageParts<'_> {
        StageParts {
            critic: &mut self.critic,
            volume_critic: self.volume_critic.as_mut(),
            generator_opt: &mut self.opt,
            reconstruction_noise_opt: self.noise_opt.as_mut(),
        }
    }
}

/// The RMSE between renderings of `volume` and the level's images over up to `max_views`
/// views: SinGAN sets a scale's noise amplitude from the error of the upsampled coarser
/// reconstruction.
pub(super) fn reconstruction_rmse(
    renderer: &ViewRenderer,
    volume: &Tensor,
    level: &DatasetLevel,
    max_views: usize,
) -> Result<f64> {
    let views = level.cameras.len().min(max_views);
    let cameras: Vec<_> = level.cameras.iter().take(views).collect();
    let (rgb, _) = renderer.render(volume, &cameras)?;
    let real = level.images.narrow(0, 0, views)?;
    let mse = (rgb - real)?.sqr()?.mean(D::Minus1)?.mean_all()?;
    Ok(f64::from(mse.to_scalar::<f32>()?).sqrt())
}

/// The critic's view of `volume` from `cameras`: colour, depth and opacity as the real batch
/// has them (its first `channels`; the renderer may make opacity for the reconstruction loss
/// alone).
fn critic_view(
    renderer: &ViewRenderer,
    volume: &Tensor,
    cameras: &[&volrender::Camera],
    channels: usize,
) -> Result<Tensor> {
    Ok(renderer
        .render_joined(volume, cameras)?
        .narrow(1, 0, channels)?)
}

/// The critics' real batch `(V, C, h, w)` of a level: colour, then depth divided by
/// `depth_norm` (with `ablations.use_depth`), then alpha (with `critics.opacity`), the channels
/// [`ViewRenderer::render_joined`] renders for the fakes.
fn critic_input(config: &TrainConfig, level: &DatasetLevel, depth_norm: f32) -> Result<Tensor> {
    let depth = (&level.depths / f64::from(depth_norm))?;
    let channels: Vec<&Tensor> = std::iter::once(&level.images)
        .chain(config.ablations.use_depth.then_some(&depth))
        .chain(config.critics.opacity.then_some(&level.opacity))
        .collect();
    Ok(Tensor::cat(&channels, 1)?)
}

#[cfg(test)]
mod tests {
    use candle_core::{Device, Tensor};

    use super::{critic_input, masked_mse};
    use crate::config::TrainConfig;
    use rgbd_dataset::DatasetLevel;

    #[test]
    fn critic_input_stacks_colour_depth_and_alpha_as_configured() {
        let plane = |value: f32| Tensor::full(value, (2, 1, 3, 3), &Device::Cpu).unwrap();
        let level = DatasetLevel {
            images: Tensor::full(0.25f32, (2, 3, 3, 3), &Device::Cpu).unwrap(),
            depths: plane(2.0),
            opacity: plane(0.5),
            depth_mask: None,
            cameras: Vec::new(),
        };
        let channel_means = |config: &TrainConfig| -> Vec<f32> {
            let input = critic_input(config, &level, 4.0).unwrap();
            let means = input.mean_keepdim(3).unwrap().mean_keepdim(2).unwrap();
            means
                .mean(0)
                .unwrap()
                .flatten_all()
                .unwrap()
                .to_vec1()
                .unwrap()
        };
        let both = TrainConfig::preset("micro").unwrap();
        // Colour, depth / depth_norm, alpha.
        assert_eq!(channel_means(&both), [0.25, 0.25, 0.25, 0.5, 0.5]);
        let no_depth = both.clone().with(|c| {
            c.ablations.use_depth = false;
        });
        assert_eq!(channel_means(&no_depth), [0.25, 0.25, 0.25, 0.5]);
        let paper_like = both.with(|c| {
            c.critics.opacity = false;
        });
        assert_eq!(channel_means(&paper_like), [0.25, 0.25, 0.25, 0.5]);
        let colour_only = paper_like.with(|c| {
            c.ablations.use_depth = false;
        });
        assert_eq!(channel_means(&colour_only), [0.25, 0.25, 0.25]);
    }

    #[test]
    fn masked_mse_counts_only_known_pixels() {
        let t = |v: &[f32]| Tensor::new(v, &Device::Cpu).unwrap();
        // Errors 1, 2, 3, 4 with weights 1, 0.5, 0, 1: (1 + 0.5 * 4 + 16) / 2.5 = 7.6.
        let loss = masked_mse(
            &t(&[1.0, 2.0, 3.0, 4.0]),
            &t(&[0.0; 4]),
            &t(&[1.0, 0.5, 0.0, 1.0]),
        )
        .unwrap();
        assert!((loss.to_scalar::<f32>().unwrap() - 7.6).abs() < 1e-6);
        // Nothing known: no loss rather than NaN.
        let none = masked_mse(&t(&[1.0]), &t(&[0.0]), &t(&[0.0])).unwrap();
        assert_eq!(none.to_scalar::<f32>().unwrap(), 0.0);
    }
}

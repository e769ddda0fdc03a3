//! Training one 3D scale n < N: G_n against the depth-conditioned critic D_n, with the
//! reconstruction of the dataset views from the fixed noise.

use std::collections::HashMap;
use std::path::Path;

use candle_core::{Tensor, D};
use radiance_volume::RadianceVolume;
use rand::Rng;

use super::colour::{chroma_distribution_loss, colour_distribution_loss};
use super::concurrent::CoarserGenerator;
use super::critic::{Critic, VolumeCritic};
use super::fitted::FittedTarget;
use super::height_profile::height_profile_loss;
use super::run::{Stage, StageParts};
use super::sample_opacity::{opacity_binary_loss, opacity_distribution_loss};
use super::StepLosses;
use crate::config::TrainConfig;
use crate::dataset::DatasetLevel;
use crate::error::Result;
use crate::model::{named_vars, SinGrav, VOLUME_CHANNELS};
use crate::optim::{Adam, WeightAverage};
use crate::render::ViewRenderer;

/// A loss on the samples' rendered opacity against the real views' alpha (both `(V, 1, h, w)`).
type OpacityLoss = fn(&Tensor, &Tensor) -> Result<Tensor>;

/// A loss on the samples' rendered colours against the real views' (both `(V, 3, h, w)`), with
/// random directions drawn from the generator.
type ColourLoss = fn(&Tensor, &Tensor, &mut rand_chacha::ChaCha8Rng) -> Result<Tensor>;

/// One iteration's random draw: the noise of the scales that train (this one, and with
/// concurrent training the coarser ones that train with it) and the volume of the frozen scales
/// below them. As in SinGAN, noise is drawn once per iteration: the critic steps see the same
/// fake (here from different views) and the generator steps refine the same draw.
struct Draw {
    trained_noise: Vec<Tensor>,
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
    /// The coarser generators that train with this one (concurrent training), coarsest first.
    coarser: Vec<CoarserGenerator>,
    /// The reconstruction (raw) of the last frozen scale, below every generator that trains;
    /// `None` when scale 1 trains.
    frozen_reconstruction: Option<Tensor>,
    /// The reconstruction noise of the scales that train ({z*_1}, zeros, or this scale's
    /// optimised z*_n).
    reconstruction_noise: Vec<Tensor>,
    /// The fitted volume at this scale's size, when the run trains against one.
    fitted: Option<FittedTarget>,
    /// The 3D critic of volumes (runs with `lambda_volume_critic > 0`), judging against
    /// `fitted`.
    volume_critic: Option<VolumeCritic>,
    /// The moving average of the weights of every generator that trains (runs with
    /// `generator_average > 0`), which they keep when the scale ends.
    average: Option<WeightAverage>,
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
    /// Sets up scale `n` (its generator already pushed onto `model`), and with concurrent
    /// training the coarser generators that train with it, on top of the frozen scales' fixed
    /// reconstruction.
    pub fn new(
        model: &'a SinGrav,
        n: usize,
        level: DatasetLevel,
        depth_norm: f32,
        previous_critic: Option<&HashMap<String, Tensor>>,
        rng: &mut impl Rng,
    ) -> Result<Self> {
        let config = model.config();
        let renderer =
            ViewRenderer::new(config, config.samples[n - 1], depth_norm, config.use_depth)
                .with_opacity(config.critic_opacity || config.lambda_opacity > 0.0);
        let real = critic_input(config, &level, depth_norm)?;
        let in_channels = real.dim(1)?;
        let critic = Critic::new(config, in_channels, previous_critic, model.device(), rng)?;
        let vars = model
            .generator_vars(n)
            .ok_or_else(|| crate::error::invalid("scale", format!("generator {n} is not built")))?;
        let opt = Adam::new(named_vars(vars), config.learning_rate, config.betas)?;
        let noise_opt = model
            .reconstruction_noise_var(n)
            .map(|z| {
                Adam::new(
                    vec![("z_star".into(), z.clone())],
                    config.reconstruction_noise_lr,
                    config.betas,
                )
            })
            .transpose()?;
        let coarser = CoarserGenerator::for_scale(model, config, n)?;
        let average = (config.generator_average > 0.0)
            .then(|| trained_generator_average(model, n - coarser.len()..=n))
            .transpose()?;
        let mut frozen_noise = model.reconstruction_noise(n)?;
        let reconstruction_noise = frozen_noise.split_off(n - 1 - coarser.len());
        let frozen_reconstruction = if frozen_noise.is_empty() {
            None
        } else {
            Some(model.generate(&frozen_noise)?.detach())
        };
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
            coarser,
            frozen_reconstruction,
            reconstruction_noise,
            fitted: None,
            volume_critic: None,
            average,
        })
    }

    /// Trains against `fitted` (resampled to this scale): the reconstruction is compared with
    /// it in 3D, weighted by the configuration's `lambda_fitted`, and with a positive
    /// `lambda_volume_critic` a 3D critic (seeded from `rng`, then copied from
    /// `previous_volume_critic`, the last scale's, where shapes agree) judges the generated
    /// volumes against it.
    pub fn with_fitted(
        mut self,
        fitted: Option<&RadianceVolume>,
        previous_volume_critic: Option<&HashMap<String, Tensor>>,
        rng: &mut impl Rng,
    ) -> Result<Self> {
        let size = self.config.volume_sizes[self.n - 1];
        self.fitted = fitted
            .map(|volume| {
                let density = self.config.density_interpolation();
                FittedTarget::new(volume, size, density, self.model.device())
            })
            .transpose()?;
        if self.config.lambda_volume_critic > 0.0 {
            if self.fitted.is_none() {
                return Err(crate::error::invalid(
                    "lambda_volume_critic",
                    "the 3D critic judges against a fitted volume, and none was given",
                ));
            }
            let channels = if self.config.volume_critic_colour {
                VOLUME_CHANNELS
            } else {
                1
            };
            self.volume_critic = Some(VolumeCritic::new(
                self.config,
                channels,
                previous_volume_critic,
                self.model.device(),
                rng,
            )?);
        }
        Ok(self)
    }

    /// The first scale whose generator trains.
    fn first_trained(&self) -> usize {
        self.n - self.coarser.len()
    }

    /// Draws fresh noise at every scale and runs the frozen scales on it.
    fn draw(&self, rng: &mut impl Rng) -> Result<Draw> {
        let mut noise = self.model.draw_noise(self.n, rng)?;
        let trained_noise = noise.split_off(self.first_trained() - 1);
        let frozen = if noise.is_empty() {
            None
        } else {
            Some(self.model.generate(&noise)?.detach())
        };
        Ok(Draw {
            trained_noise,
            frozen,
        })
    }

    /// The generators of the last `noise.len()` scales up to this one, run on `noise` on top
    /// of the volume `frozen` of the scales below them: differentiable in those generators.
    fn run_trained(&self, frozen: Option<&Tensor>, noise: &[Tensor]) -> Result<Tensor> {
        let mut volume = frozen.cloned();
        for (scale, z) in (self.n + 1 - noise.len()..).zip(noise) {
            volume = Some(match volume {
                None => self.model.coarsest(z)?,
                Some(prev) => self.model.refine(scale, z, &prev)?,
            });
        }
        volume.ok_or_else(|| crate::error::invalid("scale", "no 3D scale to generate"))
    }

    /// The random volume of this scale for a draw, differentiable in the generators that train.
    fn fake_volume(&self, draw: &Draw) -> Result<Tensor> {
        self.run_trained(draw.frozen.as_ref(), &draw.trained_noise)
    }

    /// The reconstruction V*_n from the reconstruction noise, differentiable in the generators
    /// that train (and in this scale's z*_n when it is optimised).
    fn reconstruction(&self) -> Result<Tensor> {
        self.run_trained(
            self.frozen_reconstruction.as_ref(),
            &self.reconstruction_noise,
        )
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
        let views = self.views();
        let draw = if adversarial {
            Some(self.draw(rng)?)
        } else {
            None
        };
        if let Some(draw) = &draw {
            let fake_volume = self.fake_volume(draw)?.detach();
            if let (Some(critic), Some(fitted)) = (&mut self.volume_critic, &self.fitted) {
                let colour = self.config.volume_critic_colour;
                let real = fitted.features(colour)?;
                let fake =
                    fitted.volume_features(&fake_volume, &self.config.activation(), colour)?;
                // One real volume and this iteration's one fake at every step.
                let (critic, penalty) =
                    critic.steps_on(self.config, rng, |_| Ok((real.clone(), fake.clone())))?;
                losses.volume_critic = Some(critic);
                losses.volume_penalty = Some(penalty);
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
            losses.critic = Some(critic);
            losses.penalty = Some(penalty);
        }
        let (mut adversarial_sum, mut color_sum, mut depth_sum) = (0.0, 0.0, 0.0);
        let (mut fitted_sum, mut opacity_sum, mut volume_adversarial_sum) = (0.0, 0.0, 0.0);
        // The distribution terms on the samples' colours, each with its weight.
        let colour_terms: [(f64, ColourLoss); 2] = [
            (self.config.lambda_colour, colour_distribution_loss),
            (self.config.lambda_chroma, chroma_distribution_loss),
        ];
        let mut colour_sums = [0.0f32; 2];
        // The terms on the samples' rendered opacity, each with its weight at this scale.
        let opacity_terms: [(f64, OpacityLoss); 3] = [
            (self.config.lambda_height_profile, height_profile_loss),
            (self.config.opacity_binary_weight(self.n), |opacity, _| {
                opacity_binary_loss(opacity)
            }),
            (
                self.config.lambda_opacity_distribution,
                opacity_distribution_loss,
            ),
        ];
        let mut opacity_sums = [0.0f32; 3];
        for _ in 0..self.config.g_steps {
            let mut total = Tensor::zeros((), candle_core::DType::F32, self.model.device())?;
            if let Some(draw) = &draw {
                let fake_views = pick_views(rng, views, self.config.views(self.n).generated);
                let fake_volume = self.fake_volume(draw)?;
                if let (Some(critic), Some(fitted)) = (&self.volume_critic, &self.fitted) {
                    let features = fitted.volume_features(
                        &fake_volume,
                        &self.config.activation(),
                        self.config.volume_critic_colour,
                    )?;
                    let loss =
                        (critic.generator_loss(&features)? * self.config.lambda_volume_critic)?;
                    volume_adversarial_sum += loss.to_scalar::<f32>()?;
                    total = (total + loss)?;
                }
                let fake = critic_view(
                    &self.renderer,
                    &fake_volume,
                    &self.cameras(&fake_views),
                    self.real.dim(1)?,
                )?;
                let adv = self.critic.generator_loss(&fake)?;
                adversarial_sum += adv.to_scalar::<f32>()?;
                total = (total + adv)?;
                if colour_terms.iter().any(|(weight, _)| *weight > 0.0) {
                    let (colour, real) = (
                        fake.narrow(1, 0, 3)?,
                        select(&self.level.images, &fake_views)?,
                    );
                    for ((weight, loss), sum) in colour_terms.iter().zip(&mut colour_sums) {
                        if *weight > 0.0 {
                            let loss = (loss(&colour, &real, rng)? * *weight)?;
                            *sum += loss.to_scalar::<f32>()?;
                            total = (total + loss)?;
                        }
                    }
                }
                if opacity_terms.iter().any(|(weight, ..)| *weight > 0.0) {
                    // Validation keeps these weights at 0 unless the critics' views end with
                    // the rendered opacity.
                    let opacity = fake.narrow(1, fake.dim(1)? - 1, 1)?;
                    let alpha = select(&self.level.opacity, &fake_views)?;
                    for ((weight, loss), sum) in opacity_terms.iter().zip(&mut opacity_sums) {
                        if *weight > 0.0 {
                            let loss = (loss(&opacity, &alpha)? * *weight)?;
                            *sum += loss.to_scalar::<f32>()?;
                            total = (total + loss)?;
                        }
                    }
                }
            }
            let rec_views = pick_views(rng, views, self.config.views(self.n).reconstruction);
            let reconstruction = self.reconstruction()?;
            if let (Some(fitted), true) = (&self.fitted, self.config.lambda_fitted > 0.0) {
                let loss = (fitted.loss(&reconstruction, &self.config.activation())?
                    * self.config.lambda_fitted)?;
                fitted_sum += loss.to_scalar::<f32>()?;
                total = (total + loss)?;
            }
            let maps = self
                .renderer
                .render_all(&reconstruction, &self.cameras(&rec_views))?;
            let (rgb, depth) = (maps.rgb, maps.depth);
            if let (Some(opacity), true) = (&maps.opacity, self.config.lambda_opacity > 0.0) {
                let alpha = select(&self.level.opacity, &rec_views)?;
                let loss = (mse(opacity, &alpha)? * self.config.lambda_opacity)?;
                opacity_sum += loss.to_scalar::<f32>()?;
                total = (total + loss)?;
            }
            let color =
                (mse(&rgb, &select(&self.level.images, &rec_views)?)? * self.config.lambda_color)?;
            color_sum += color.to_scalar::<f32>()?;
            total = (total + color)?;
            if let Some(depth) = depth {
                let real_depth = select(&self.real, &rec_views)?.narrow(1, 3, 1)?;
                let error = match &self.level.depth_mask {
                    None => mse(&depth, &real_depth)?,
                    Some(mask) => masked_mse(&depth, &real_depth, &select(mask, &rec_views)?)?,
                };
                let depth = (error * self.config.lambda_depth)?;
                depth_sum += depth.to_scalar::<f32>()?;
                total = (total + depth)?;
            }
            let grads = total.backward()?;
            self.opt.step(&grads)?;
            if let Some(opt) = &mut self.noise_opt {
                opt.step(&grads)?;
            }
            for coarser in &mut self.coarser {
                coarser.opt.step(&grads)?;
            }
            if let Some(average) = &mut self.average {
                average.update()?;
            }
        }
        let steps = self.config.g_steps as f32;
        losses.color = color_sum / steps;
        losses.depth = self.config.use_depth.then_some(depth_sum / steps);
        losses.adversarial = adversarial.then_some(adversarial_sum / steps);
        losses.fitted = (self.fitted.is_some() && self.config.lambda_fitted > 0.0)
            .then_some(fitted_sum / steps);
        losses.volume_adversarial =
            (adversarial && self.volume_critic.is_some()).then_some(volume_adversarial_sum / steps);
        losses.opacity = (self.config.lambda_opacity > 0.0).then_some(opacity_sum / steps);
        // A sample term's mean, reported when it acted: in adversarial iterations, weighted.
        let reported = |weight: f64, sum: f32| (adversarial && weight > 0.0).then_some(sum / steps);
        losses.colour_distribution = reported(colour_terms[0].0, colour_sums[0]);
        losses.chroma_distribution = reported(colour_terms[1].0, colour_sums[1]);
        losses.height_profile = reported(opacity_terms[0].0, opacity_sums[0]);
        losses.opacity_binary = reported(opacity_terms[1].0, opacity_sums[1]);
        losses.opacity_distribution = reported(opacity_terms[2].0, opacity_sums[2]);
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

    fn finish(&mut self) -> Result<()> {
        match &self.average {
            Some(average) => average.apply(),
            None => Ok(()),
        }
    }

    fn parts(&mut self) -> StageParts<'_> {
        StageParts {
            critic: &mut self.critic,
            volume_critic: self.volume_critic.as_mut(),
            generator_opt: &mut self.opt,
            coarser_generators: &mut self.coarser,
            reconstruction_noise_opt: self.noise_opt.as_mut(),
            generator_average: self.average.as_mut(),
        }
    }
}

/// The weight average of the generators of `scales` (names `{scale}.{variable}`), with the
/// configuration's decay.
fn trained_generator_average(
    model: &SinGrav,
    scales: std::ops::RangeInclusive<usize>,
) -> Result<WeightAverage> {
    let mut params = Vec::new();
    for scale in scales {
        let vars = model.generator_vars(scale).ok_or_else(|| {
            crate::error::invalid("scale", format!("generator {scale} is not built"))
        })?;
        params.extend(
            named_vars(vars)
                .into_iter()
                .map(|(name, var)| (format!("{scale}.{name}"), var)),
        );
    }
    WeightAverage::new(params, model.config().generator_average)
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
/// `depth_norm` (with `use_depth`), then alpha (with `critic_opacity`), the channels
/// [`ViewRenderer::render_joined`] renders for the fakes.
fn critic_input(config: &TrainConfig, level: &DatasetLevel, depth_norm: f32) -> Result<Tensor> {
    let depth = (&level.depths / f64::from(depth_norm))?;
    let channels: Vec<&Tensor> = std::iter::once(&level.images)
        .chain(config.use_depth.then_some(&depth))
        .chain(config.critic_opacity.then_some(&level.opacity))
        .collect();
    Ok(Tensor::cat(&channels, 1)?)
}

/// Where a picture of a scale's samples goes.
pub(super) fn picture_path(run_dir: &Path, scale: usize) -> std::path::PathBuf {
    run_dir.join("samples").join(format!("scale_{scale}.png"))
}

#[cfg(test)]
mod tests {
    use candle_core::{Device, Tensor};

    use super::{critic_input, masked_mse};
    use crate::config::TrainConfig;
    use crate::dataset::DatasetLevel;

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
        let no_depth = TrainConfig {
            use_depth: false,
            ..both.clone()
        };
        assert_eq!(channel_means(&no_depth), [0.25, 0.25, 0.25, 0.5]);
        let paper_like = TrainConfig {
            critic_opacity: false,
            ..both
        };
        assert_eq!(channel_means(&paper_like), [0.25, 0.25, 0.25, 0.5]);
        let colour_only = TrainConfig {
            use_depth: false,
            ..paper_like
        };
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

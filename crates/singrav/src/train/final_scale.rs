//! Training the last scale N: the 2D upsampler G_N doubles renderings of the frozen 3D pyramid,
//! judged by the joint critic on `[G_N output, naive upsample]`, with the colour reconstruction
//! and the sliced Wasserstein texture loss.

use std::collections::HashMap;

use candle_core::Tensor;
use patch_gan::upsample_bilinear2x;
use rand::Rng;
use swd_loss::Vgg19;

use rgbd_dataset::DatasetLevel;

use super::critic::Critic;
use super::losses::{LossTerm, StepLosses, StepMeans, StepTerms};
use super::stage::{Stage, StageParts};
use super::texture::{texture_loss, ViewTexture};
use super::volume_scale::{mse, pick_views, select};
use crate::config::TrainConfig;
use crate::error::Result;
use crate::model::{named_vars, SinGrav};
use crate::optim::Adam;
use crate::render::ViewRenderer;

/// The state of the last scale's training.
pub(super) struct FinalScale<'a> {
    model: &'a SinGrav,
    config: &'a TrainConfig,
    /// Dataset at the last 3D scale's resolution (the upsampler's input size).
    coarse: DatasetLevel,
    /// Dataset at the final resolution.
    fine: DatasetLevel,
    /// Real joint critic inputs `[x_N, up(x_{N-1})]`, `(V, 6, 2h, 2w)`.
    real: Tensor,
    /// Renderings of the frozen reconstruction V*_{N-1} from every view, `(V, 3, h, w)`.
    reconstruction: Tensor,
    renderer: ViewRenderer,
    critic: Critic,
    opt: Adam,
    texture: Option<ViewTexture>,
}

impl<'a> FinalScale<'a> {
    /// Sets up scale N (the upsampler already pushed onto `model`); `vgg` holds the VGG-19
    /// weights when the configuration's SWD loss compares VGG-19 features.
    pub fn new(
        model: &'a SinGrav,
        coarse: DatasetLevel,
        fine: DatasetLevel,
        previous_critic: Option<&HashMap<String, Tensor>>,
        vgg: Option<&Vgg19>,
        rng: &mut impl Rng,
    ) -> Result<Self> {
        let config = model.config();
        let last = config.pyramid.volume_sizes.len();
        let renderer = ViewRenderer::new(config, config.pyramid.samples[last - 1], 1.0, false);
        let real = Tensor::cat(&[&fine.images, &upsample_bilinear2x(&coarse.images)?], 1)?;
        let critic = Critic::new(config, real.dim(1)?, previous_critic, model.device(), rng)?;
        let vars = model
            .upsampler_vars()
            .ok_or_else(|| crate::error::invalid("scale", "the upsampler is not built"))?;
        let opt = Adam::new(
            named_vars(vars),
            config.schedule.learning_rate,
            config.schedule.betas,
        )?;
        let frozen = model.generate(&model.reconstruction_noise(last)?)?.detach();
        let cameras: Vec<_> = coarse.cameras.iter().collect();
        let (reconstruction, _) = renderer.render(&frozen, &cameras)?;
        let texture = texture_loss(config, vgg, &fine.images)?;
        Ok(Self {
            model,
            config,
            coarse,
            fine,
            real,
            reconstruction,
            renderer,
            critic,
            opt,
            texture,
        })
    }

    /// A random raw volume of the frozen 3D pyramid (drawn once per iteration, as SinGAN
    /// draws noise once per iteration).
    fn fake_volume(&self, rng: &mut impl Rng) -> Result<Tensor> {
        let noise = self
            .model
            .draw_noise(self.config.pyramid.volume_sizes.len(), rng)?;
        Ok(self.model.generate(&noise)?.detach())
    }

    /// Renderings `(V, 3, h, w)` of `volume` from `views`.
    fn fake_rendering(&self, volume: &Tensor, views: &[usize]) -> Result<Tensor> {
        render_views(&self.renderer, volume, &self.coarse.cameras, views)
    }
}

/// Colour renderings `(V, 3, h, w)` of `volume` from `cameras[views]`.
fn render_views(
    renderer: &ViewRenderer,
    volume: &Tensor,
    cameras: &[volrender::Camera],
    views: &[usize],
) -> Result<Tensor> {
    let cameras: Vec<_> = views.iter().map(|&v| &cameras[v]).collect();
    Ok(renderer.render(volume, &cameras)?.0)
}

/// The joint critic input `[G_N(x), up(x)]`.
fn joint(upsampled: &Tensor, coarse: &Tensor) -> Result<Tensor> {
    Ok(Tensor::cat(&[upsampled, &upsample_bilinear2x(coarse)?], 1)?)
}

impl Stage for FinalScale<'_> {
    fn iteration(
        &mut self,
        adversarial: bool,
        rng: &mut rand_chacha::ChaCha8Rng,
    ) -> Result<StepLosses> {
        let mut losses = StepLosses::default();
        let views = self.coarse.cameras.len();
        let fake_volume = if adversarial {
            Some(self.fake_volume(rng)?)
        } else {
            None
        };
        if let Some(volume) = &fake_volume {
            let (model, renderer, cameras) = (self.model, &self.renderer, &self.coarse.cameras);
            let batch = self.config.views(self.config.scales()).generated;
            let (critic, penalty) =
                self.critic
                    .steps(self.config, batch, &self.real, rng, |views| {
                        let coarse = render_views(renderer, volume, cameras, views)?;
                        joint(&model.upsample_images(&coarse)?, &coarse)
                    })?;
            losses.set(LossTerm::Critic, critic);
            losses.set(LossTerm::Penalty, penalty);
        }
        let mut means = StepMeans::new();
        for _ in 0..self.config.schedule.g_steps {
            let mut terms = StepTerms::new();
            if let Some(volume) = &fake_volume {
                let fake_views = pick_views(
                    rng,
                    views,
                    self.config.views(self.config.scales()).generated,
                );
                let coarse = self.fake_rendering(volume, &fake_views)?;
                let upsampled = self.model.upsample_images(&coarse)?;
                let adv = self.critic.generator_loss(&joint(&upsampled, &coarse)?)?;
                terms.add(LossTerm::Adversarial, adv);
                if let Some(texture) = &self.texture {
                    let swd = texture.loss(&upsampled, &fake_views, rng)?;
                    terms.add(LossTerm::Swd, (swd * self.config.losses.swd)?);
                }
            }
            let rec_views = pick_views(
                rng,
                views,
                self.config.views(self.config.scales()).reconstruction,
            );
            let rebuilt = self
                .model
                .upsample_images(&select(&self.reconstruction, &rec_views)?)?;
            let real = select(&self.fine.images, &rec_views)?;
            terms.add(
                LossTerm::Colour,
                (mse(&rebuilt, &real)? * self.config.losses.rgb)?,
            );
            means.add(&terms)?;
            self.opt
                .step(&terms.total(self.model.device())?.backward()?)?;
        }
        means.write_into(&mut losses);
        Ok(losses)
    }

    fn picture_rows(
        &self,
        rng: &mut rand_chacha::ChaCha8Rng,
        count: usize,
    ) -> Result<Vec<Vec<Tensor>>> {
        let mut row = vec![
            self.fine.images.get(0)?,
            self.model
                .upsample_images(&self.reconstruction.narrow(0, 0, 1)?)?
                .get(0)?,
        ];
        for _ in 0..count {
            let coarse = self.fake_rendering(&self.fake_volume(rng)?, &[0])?;
            row.push(self.model.upsample_images(&coarse)?.get(0)?);
        }
        Ok(vec![row])
    }

    fn parts(&mut self) -> StageParts<'_> {
        StageParts {
            critic: &mut self.critic,
            volume_critic: None,
            generator_opt: &mut self.opt,
            reconstruction_noise_opt: None,
        }
    }
}

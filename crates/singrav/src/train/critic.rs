//! The patch critics of one scale (of renderings, and of volumes) and their WGAN-GP update.

use std::collections::HashMap;

use candle_core::{DType, Device, Tensor};
use candle_nn::{VarBuilder, VarMap};
use patch_gan::{GradientPenalty, PatchDiscriminator, PatchDiscriminatorConfig};

use super::volume_scale::{pick_views, select};
use crate::config::TrainConfig;
use crate::error::{Error, Result};
use crate::model::{copy_matching, named_vars, seeded_init};
use crate::optim::Adam;

/// A scale's critic over `AXES` spatial axes (2: renderings, 3: volumes), its variables and
/// its optimiser.
pub(super) struct Critic<const AXES: usize = 2> {
    pub net: PatchDiscriminator<AXES>,
    pub vars: VarMap,
    pub opt: Adam,
}

/// The critic of a scale's volumes (opacity and opacity-weighted colour per voxel).
pub(super) type VolumeCritic = Critic<3>;

impl<const AXES: usize> Critic<AXES> {
    /// A critic over `in_channels`, seeded from `rng`, then copied from `previous` (the last
    /// scale's critic) where shapes agree.
    pub fn new(
        config: &TrainConfig,
        in_channels: usize,
        previous: Option<&HashMap<String, Tensor>>,
        device: &Device,
        rng: &mut impl rand::Rng,
    ) -> Result<Self> {
        let vars = VarMap::new();
        let cfg = PatchDiscriminatorConfig {
            layers: config.pyramid.layers,
            channels: config.pyramid.channels,
            in_channels,
        };
        let net = PatchDiscriminator::<AXES>::new(
            &cfg,
            VarBuilder::from_varmap(&vars, DType::F32, device),
        )?;
        seeded_init(&vars, rng)?;
        if let Some(previous) = previous {
            copy_matching(previous, &vars)?;
        }
        let opt = Adam::new(
            named_vars(&vars),
            config.schedule.learning_rate,
            config.schedule.betas,
        )?;
        Ok(Self { net, vars, opt })
    }

    /// One critic step on a real and a fake batch (the fake detached); returns the critic loss
    /// and the weighted penalty.
    pub fn step(
        &mut self,
        real: &Tensor,
        fake: &Tensor,
        gp_weight: f64,
        rng: &mut impl rand::Rng,
    ) -> Result<(f32, f32)> {
        let fake = fake.detach();
        let loss = self.net.critic_loss(real, &fake)?;
        let penalty = GradientPenalty {
            weight: gp_weight,
            ..GradientPenalty::default()
        };
        let gp = match self.net.gradient_penalty(real, &fake, penalty, rng) {
            Err(patch_gan::Error::SecondOrderDisabled) => {
                return Err(Error::Invalid {
                    what: "environment".into(),
                    why: "training on a GPU needs CANDLE_GRAD_DO_NOT_DETACH=1 set before the \
                          first backward pass (there the gradient penalty differentiates a \
                          gradient); the volgen CLI sets it itself"
                        .into(),
                })
            }
            other => other?,
        };
        let total = (&loss + &gp)?;
        self.opt.step(&total.backward()?)?;
        Ok((loss.to_scalar::<f32>()?, gp.to_scalar::<f32>()?))
    }

    /// The generator's adversarial loss on a fake batch (differentiable).
    pub fn generator_loss(&self, fake: &Tensor) -> Result<Tensor> {
        Ok(patch_gan::generator_loss(&self.net.score(fake)?)?)
    }

    /// The critic's part of an iteration: `config.schedule.d_steps` steps, each on the (real, fake)
    /// batches `batches` draws from `rng`; returns the mean critic loss and penalty.
    pub fn steps_on(
        &mut self,
        config: &TrainConfig,
        rng: &mut rand_chacha::ChaCha8Rng,
        mut batches: impl FnMut(&mut rand_chacha::ChaCha8Rng) -> Result<(Tensor, Tensor)>,
    ) -> Result<(f32, f32)> {
        let (mut critic_sum, mut penalty_sum) = (0.0, 0.0);
        for _ in 0..config.schedule.d_steps {
            let (real, fake) = batches(rng)?;
            let (c, p) = self.step(&real, &fake, config.critics.gradient_penalty, rng)?;
            critic_sum += c;
            penalty_sum += p;
        }
        let steps = config.schedule.d_steps as f32;
        Ok((critic_sum / steps, penalty_sum / steps))
    }
}

impl Critic<2> {
    /// The critic's part of an iteration: `config.schedule.d_steps` steps, each on `batch_views`
    /// random real views against the fake batch `fake_batch(views)` of as many random views;
    /// returns the mean critic loss and penalty.
    pub fn steps(
        &mut self,
        config: &TrainConfig,
        batch_views: usize,
        real: &Tensor,
        rng: &mut rand_chacha::ChaCha8Rng,
        fake_batch: impl Fn(&[usize]) -> Result<Tensor>,
    ) -> Result<(f32, f32)> {
        let views = real.dim(0)?;
        self.steps_on(config, rng, |rng| {
            let real = select(real, &pick_views(rng, views, batch_views))?;
            let fake = fake_batch(&pick_views(rng, views, batch_views))?;
            Ok((real, fake))
        })
    }
}

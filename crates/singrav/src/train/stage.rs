//! One scale's training as the trainer drives it ([`Stage`]), and what of it a checkpoint
//! saves beside the generators' weights ([`StageParts`]).

use std::collections::HashMap;
use std::path::Path;

use candle_core::{Device, Tensor};

use super::critic::{Critic, VolumeCritic};
use super::losses::StepLosses;
use crate::error::{Error, Result};
use crate::model::{load_into, var_tensors};
use crate::optim::Adam;

/// Checkpoint names of the 2D and 3D critics' weights.
pub(super) const CRITIC_PREFIX: &str = "d.";
pub(super) const VOLUME_CRITIC_PREFIX: &str = "d3.";
/// Checkpoint name prefixes of the optimisers: the generator's, the 2D and 3D critics', and the
/// reconstruction noise's.
const GENERATOR_OPT_PREFIX: &str = "opt_g.";
const CRITIC_OPT_PREFIX: &str = "opt_d.";
const VOLUME_CRITIC_OPT_PREFIX: &str = "opt_d3.";
const NOISE_OPT_PREFIX: &str = "opt_z.";

/// One scale's training, as the trainer drives it.
pub(super) trait Stage {
    /// Runs one iteration (`schedule.d_steps` critic steps when `adversarial`, then `schedule.g_steps` generator
    /// steps) drawing all randomness from `rng`.
    fn iteration(
        &mut self,
        adversarial: bool,
        rng: &mut rand_chacha::ChaCha8Rng,
    ) -> Result<StepLosses>;
    /// Rows of the scale's picture: real view, reconstruction, then `count` samples.
    fn picture_rows(
        &self,
        rng: &mut rand_chacha::ChaCha8Rng,
        count: usize,
    ) -> Result<Vec<Vec<Tensor>>>;
    /// The critics and the optimisers (for checkpoints).
    fn parts(&mut self) -> StageParts<'_>;
}

/// What a stage trains beside its generator's weights, as a checkpoint saves it.
pub(super) struct StageParts<'a> {
    /// The 2D critic (checkpoint names `d.*`, its optimiser `opt_d.*`).
    pub critic: &'a mut Critic,
    /// The 3D critic, when the run has one (`d3.*`, `opt_d3.*`).
    pub volume_critic: Option<&'a mut VolumeCritic>,
    /// The generator's optimiser (`opt_g.*`).
    pub generator_opt: &'a mut Adam,
    /// The optimiser of the scale's reconstruction noise z*_n (`opt_z.*`), when the run
    /// optimises it.
    pub reconstruction_noise_opt: Option<&'a mut Adam>,
}

impl StageParts<'_> {
    /// The critics' weights by checkpoint name (`d.*`, `d3.*`).
    pub fn critic_tensors(&self) -> HashMap<String, Tensor> {
        let named = |prefix: &str, vars: &candle_nn::VarMap| {
            var_tensors(vars)
                .into_iter()
                .map(|(name, t)| (format!("{prefix}{name}"), t))
                .collect::<Vec<_>>()
        };
        let mut tensors: HashMap<_, _> = named(CRITIC_PREFIX, &self.critic.vars)
            .into_iter()
            .collect();
        if let Some(critic) = &self.volume_critic {
            tensors.extend(named(VOLUME_CRITIC_PREFIX, &critic.vars));
        }
        tensors
    }

    /// The critics' weights and every optimiser's state by checkpoint name, with the
    /// generator's and the 2D critic's step counts.
    pub fn tensors(&self) -> (HashMap<String, Tensor>, (usize, usize)) {
        let mut tensors = self.critic_tensors();
        let (g_state, g_steps) = self.generator_opt.state(GENERATOR_OPT_PREFIX);
        let (d_state, d_steps) = self.critic.opt.state(CRITIC_OPT_PREFIX);
        tensors.extend(g_state);
        tensors.extend(d_state);
        if let Some(opt) = &self.reconstruction_noise_opt {
            // It steps with the scale's generator, so `g_steps` counts its steps too.
            tensors.extend(opt.state(NOISE_OPT_PREFIX).0);
        }
        if let Some(critic) = &self.volume_critic {
            // It steps with the 2D critic, so `d_steps` counts its steps too.
            tensors.extend(critic.opt.state(VOLUME_CRITIC_OPT_PREFIX).0);
        }
        (tensors, (g_steps, d_steps))
    }

    /// Restores the critics and the optimisers from a mid-scale checkpoint at `path` whose
    /// generator and 2D critic had taken `optimizer_steps`.
    pub fn restore(
        self,
        tensors: &HashMap<String, Tensor>,
        (g_steps, d_steps): (usize, usize),
        path: &Path,
        device: &Device,
    ) -> Result<()> {
        let fail = |why: String| Error::Checkpoint {
            path: path.to_path_buf(),
            why,
        };
        load_into(&self.critic.vars, tensors, CRITIC_PREFIX, device).map_err(fail)?;
        self.generator_opt
            .restore(tensors, GENERATOR_OPT_PREFIX, g_steps)
            .map_err(fail)?;
        if let Some(opt) = self.reconstruction_noise_opt {
            opt.restore(tensors, NOISE_OPT_PREFIX, g_steps)
                .map_err(fail)?;
        }
        self.critic
            .opt
            .restore(tensors, CRITIC_OPT_PREFIX, d_steps)
            .map_err(fail)?;
        if let Some(critic) = self.volume_critic {
            load_into(&critic.vars, tensors, VOLUME_CRITIC_PREFIX, device).map_err(fail)?;
            critic
                .opt
                .restore(tensors, VOLUME_CRITIC_OPT_PREFIX, d_steps)
                .map_err(fail)?;
        }
        Ok(())
    }
}

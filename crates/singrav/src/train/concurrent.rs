//! ConSinGAN's concurrent training: the coarser generators that keep training, each with its
//! own optimiser and learning-rate factor, while a 3D scale trains.

use crate::config::TrainConfig;
use crate::error::{invalid, Result};
use crate::model::{named_vars, SinGrav};
use crate::optim::Adam;

/// A coarser generator that trains on the current scale's losses.
pub(super) struct CoarserGenerator {
    /// Its 3D scale, 1-based.
    pub scale: usize,
    /// Its learning rate is the current scale's times this.
    pub rate_factor: f64,
    /// Its own optimiser: the moments of its last scale's optimiser are not kept, as
    /// ConSinGAN's new optimiser per stage does not keep them.
    pub opt: Adam,
}

impl CoarserGenerator {
    /// The coarser generators training with scale `n`, coarsest first
    /// ([`TrainConfig::concurrent_scales`]).
    pub fn for_scale(model: &SinGrav, config: &TrainConfig, n: usize) -> Result<Vec<Self>> {
        config
            .concurrent_scales(n)
            .into_iter()
            .map(|(scale, rate_factor)| {
                let vars = model.generator_vars(scale).ok_or_else(|| {
                    invalid("concurrent", format!("generator {scale} is not built"))
                })?;
                Ok(Self {
                    scale,
                    rate_factor,
                    opt: Adam::new(
                        named_vars(vars),
                        config.learning_rate * rate_factor,
                        config.betas,
                    )?,
                })
            })
            .collect()
    }

    /// Where a checkpoint keeps its optimiser's state.
    pub fn checkpoint_prefix(&self) -> String {
        format!("opt_g{}.", self.scale)
    }
}

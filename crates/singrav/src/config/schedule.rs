//! Per-scale iterations and views, and the changes of shape the CLI offers (fewer scales,
//! other iteration counts, other reconstruction views).

use serde::{Deserialize, Serialize};

use super::TrainConfig;
use crate::error::{invalid, Result};

/// How many views one training step of a scale renders.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScaleViews {
    /// Views of the critic's real and fake batches and of the generator's adversarial
    /// renderings.
    pub generated: usize,
    /// Views of the reconstruction loss per generator step.
    pub reconstruction: usize,
}

impl ScaleViews {
    /// `views` views for both.
    pub fn same(views: usize) -> Self {
        Self {
            generated: views,
            reconstruction: views,
        }
    }
}

/// How long one scale trains. One iteration is `d_steps` critic steps, then `g_steps`
/// generator steps; the first `reconstruction_only` iterations skip the critic and train the
/// reconstruction alone (a quarter in the presets, as the paper's 20 of 80 epochs).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScaleSchedule {
    /// Iterations of the scale.
    pub iterations: usize,
    /// The first iterations that train the reconstruction only.
    pub reconstruction_only: usize,
}

impl ScaleSchedule {
    /// `iterations` iterations, the first quarter reconstruction-only.
    pub fn quarter_reconstruction(iterations: usize) -> Self {
        Self {
            iterations,
            reconstruction_only: iterations / 4,
        }
    }
}

/// The same schedule for all `scales` scales.
pub(super) fn uniform_schedule(iterations: usize, scales: usize) -> Vec<ScaleSchedule> {
    vec![ScaleSchedule::quarter_reconstruction(iterations); scales]
}

impl TrainConfig {
    /// The views per step of scale `n` (1-based).
    ///
    /// # Panics
    /// If `n` is not a scale of this configuration (see [`TrainConfig::validate`]).
    pub fn views(&self, n: usize) -> ScaleViews {
        match &self.schedule.scale_views {
            Some(views) => views[n - 1],
            None => ScaleViews::same(self.schedule.views_per_step),
        }
    }

    /// Sets the reconstruction loss's views per generator step at every 3D scale to `views`,
    /// keeping each scale's generated views (and the upsampler's views).
    pub fn with_reconstruction_views(mut self, views: usize) -> Self {
        let mut all: Vec<ScaleViews> = (1..=self.scales()).map(|n| self.views(n)).collect();
        let upsampler = all.len() - 1;
        for scale in &mut all[..upsampler] {
            scale.reconstruction = views;
        }
        self.schedule.scale_views = Some(all);
        self
    }

    /// The schedule of scale `n` (1-based).
    ///
    /// # Panics
    /// If `n` is not a scale of this configuration (see [`TrainConfig::validate`]).
    pub fn scale_schedule(&self, n: usize) -> ScaleSchedule {
        self.schedule.scales[n - 1]
    }

    /// Iterations of all scales before scale `n` (1-based).
    pub fn iterations_before(&self, n: usize) -> usize {
        self.schedule.scales[..n - 1]
            .iter()
            .map(|s| s.iterations)
            .sum()
    }

    /// Iterations of the whole run.
    pub fn total_iterations(&self) -> usize {
        self.iterations_before(self.schedule.scales.len() + 1)
    }

    /// The same `iterations` at every scale, the first quarter reconstruction-only.
    pub fn with_iterations(mut self, iterations: usize) -> Self {
        self.schedule.scales = uniform_schedule(iterations, self.scales());
        self
    }

    /// The ablation "number of scales": keeps the `scales - 1` coarsest 3D scales and the
    /// upsampler, so the final images shrink with the pyramid.
    ///
    /// ```
    /// let tiny = singrav::TrainConfig::preset("tiny")?;
    /// let three = tiny.with_scales(3)?;
    /// assert_eq!(three.pyramid.volume_sizes, [16, 21]);
    /// assert_eq!(three.final_image_size(), 72);
    /// # Ok::<(), singrav::Error>(())
    /// ```
    pub fn with_scales(mut self, scales: usize) -> Result<Self> {
        if scales < 2 || scales > self.scales() {
            return Err(invalid(
                "scales",
                format!(
                    "the `{}` preset has {} scales; choose 2 to {}",
                    self.preset,
                    self.scales(),
                    self.scales()
                ),
            ));
        }
        let pyramid = &mut self.pyramid;
        pyramid.volume_sizes.truncate(scales - 1);
        pyramid.image_sizes.truncate(scales - 1);
        pyramid.samples.truncate(scales - 1);
        let schedule = &mut self.schedule;
        if let Some(&upsampler) = schedule.scales.last() {
            schedule.scales.truncate(scales - 1);
            schedule.scales.push(upsampler);
        }
        if let Some(views) = &mut schedule.scale_views {
            if let Some(&upsampler) = views.last() {
                views.truncate(scales - 1);
                views.push(upsampler);
            }
        }
        Ok(self)
    }
}

#[cfg(test)]
mod tests {
    use super::{ScaleViews, TrainConfig};

    #[test]
    fn reconstruction_views_change_the_3d_scales_only_and_follow_the_scales_ablation() {
        let micro = TrainConfig::preset("micro").unwrap();
        let config = micro.clone().with_reconstruction_views(7);
        let upsampler = config.scales();
        assert_eq!(
            config.views(1),
            ScaleViews {
                generated: micro.schedule.views_per_step,
                reconstruction: 7
            }
        );
        assert_eq!(
            config.views(upsampler),
            ScaleViews::same(micro.schedule.views_per_step)
        );
        let fewer = config.with_scales(2).unwrap();
        fewer.validate().unwrap();
        assert_eq!(fewer.views(1).reconstruction, 7);
        assert_eq!(
            fewer.views(2),
            ScaleViews::same(micro.schedule.views_per_step)
        );
    }

    #[test]
    fn views_missing_a_scale_or_zero_are_refused() {
        let mut short = TrainConfig::preset("micro").unwrap();
        short.schedule.scale_views = Some(vec![ScaleViews::same(2)]);
        let zero = TrainConfig::preset("micro")
            .unwrap()
            .with_reconstruction_views(0);
        for config in [short, zero] {
            let message = config.validate().unwrap_err().to_string();
            assert!(message.contains("schedule.scale_views"), "{message}");
        }
    }
}

//! The paper's applications on a trained pyramid: harmonising an edited volume by re-running the
//! finer generators on it, and animation by a smoothed random walk on the finer scales' noise.

use candle_core::Tensor;

use crate::error::{invalid, Result};
use crate::model::SinGrav;

/// Settings of [`SinGrav::animate`]; the default is the paper's `a = 0.58`, `x = 0.45`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WalkConfig {
    /// Pull towards the first frame's noise, `a`.
    pub anchor: f64,
    /// Momentum of the walk's steps, `x`.
    pub momentum: f64,
    /// Scales below this keep their noise fixed (they set the global layout); 1-based.
    pub first_moving_scale: usize,
}

impl Default for WalkConfig {
    fn default() -> Self {
        Self {
            anchor: 0.58,
            momentum: 0.45,
            first_moving_scale: 2,
        }
    }
}

impl SinGrav {
    /// Re-runs 3D scales `from_scale + 1 ..` on an edited raw volume of the finest 3D scale
    /// (for example one with an object removed, duplicated or moved by radiance-volume's edits):
    /// the edit is resampled to scale `from_scale`, then each finer generator adds its detail
    /// with fresh noise from `rng`, which blends the edit into the scene (the paper uses
    /// `from_scale = 3`). Returns the harmonised raw volume `(1, 4, s, s, s)`.
    pub fn harmonize(
        &self,
        edited: &Tensor,
        from_scale: usize,
        rng: &mut impl rand::Rng,
    ) -> Result<Tensor> {
        let last = self.volume_scales();
        if from_scale == 0 || from_scale >= last {
            return Err(invalid(
                "from_scale",
                format!(
                    "must be between 1 and {} (below the finest 3D scale)",
                    last - 1
                ),
            ));
        }
        let noise = self.draw_noise(last, rng)?;
        let mut volume = self.upsample_to_scale(edited, from_scale)?;
        for n in from_scale + 1..=last {
            volume = self.refine(n, &noise[n - 1], &volume)?;
        }
        Ok(volume)
    }

    /// An animation of `frames` raw volumes: the noise of scales from
    /// `walk.first_moving_scale` on follows the paper's smoothed random walk
    /// `z(t+1) = a z(1) + (1 - a) (z(t) + d(t+1))`, `d(t+1) = x (z(t) - z(t-1)) + (1 - x) mu(t+1)`
    /// with fresh noise `mu` of each scale's amplitude; coarser scales keep `z(1)`.
    pub fn animate(
        &self,
        frames: usize,
        walk: WalkConfig,
        rng: &mut impl rand::Rng,
    ) -> Result<Vec<Tensor>> {
        let scales = self.volume_scales();
        let first = self.draw_noise(scales, rng)?;
        let mut current = first.clone();
        let mut previous = first.clone();
        let mut out = Vec::with_capacity(frames);
        for t in 0..frames {
            if t > 0 {
                let mu = self.draw_noise(scales, rng)?;
                let mut next = current.clone();
                for n in walk.first_moving_scale.max(1)..=scales {
                    let i = n - 1;
                    let step = ((&current[i] - &previous[i])? * walk.momentum
                        + (&mu[i] * (1.0 - walk.momentum))?)?;
                    next[i] = ((&first[i] * walk.anchor)?
                        + ((&current[i] + step)? * (1.0 - walk.anchor))?)?;
                }
                previous = std::mem::replace(&mut current, next);
            }
            out.push(self.generate(&current)?.detach());
        }
        Ok(out)
    }
}

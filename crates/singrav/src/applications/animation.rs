//! Animation: the paper's smoothed random walk on the noise of the finer scales, one frame at a
//! time so that long animations need not hold every frame in memory.

use candle_core::Tensor;

use crate::error::{invalid, Result};
use crate::model::SinGrav;

/// Settings of [`SinGrav::animation`]; the default is the paper's `a = 0.58`, `x = 0.45`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WalkConfig {
    /// Pull towards the first frame's noise, `a` in [0, 1] (1: every frame is the first).
    pub anchor: f64,
    /// Momentum of the walk's steps, `x` in [0, 1] (0: fresh noise each step).
    pub momentum: f64,
    /// Scales below this keep their noise fixed (they set the global layout); 1-based, at most
    /// the model's finest 3D scale. The paper starts at scale 3 for its scenes; the default, 2,
    /// also moves scale 2 so that models with few scales still move.
    pub first_moving_scale: usize,
    /// Scales below this take the reconstruction's noise in every frame
    /// ([`SinGrav::draw_noise_from`]): V*'s layout, animated above it (1, the default: the
    /// first frame is a random sample). The walk moves the scales from the larger of this and
    /// `first_moving_scale` on.
    pub vary_from: usize,
}

impl Default for WalkConfig {
    fn default() -> Self {
        Self {
            anchor: 0.58,
            momentum: 0.45,
            first_moving_scale: 2,
            vary_from: 1,
        }
    }
}

impl WalkConfig {
    /// Errors unless the weights lie in [0, 1] and the first moving scale is one of the
    /// `scales` 3D scales.
    ///
    /// ```
    /// use singrav::applications::WalkConfig;
    /// assert!(WalkConfig::default().validate(5).is_ok());
    /// assert!(WalkConfig { anchor: 1.5, ..WalkConfig::default() }.validate(5).is_err());
    /// assert!(WalkConfig { first_moving_scale: 6, ..WalkConfig::default() }.validate(5).is_err());
    /// assert!(WalkConfig { vary_from: 0, ..WalkConfig::default() }.validate(5).is_err());
    /// ```
    pub fn validate(&self, scales: usize) -> Result<()> {
        for (what, value) in [("anchor", self.anchor), ("momentum", self.momentum)] {
            if !(0.0..=1.0).contains(&value) {
                return Err(invalid(
                    what,
                    format!("expected a weight between 0 and 1, got {value}"),
                ));
            }
        }
        if !(1..=scales).contains(&self.first_moving_scale) {
            return Err(invalid(
                "first_moving_scale",
                format!(
                    "expected one of the model's 3D scales 1 to {scales}, got {}",
                    self.first_moving_scale
                ),
            ));
        }
        crate::model::check_vary_from(self.vary_from, scales)
    }
}

/// The frames of an animation, as raw volumes `(1, 4, s, s, s)` of the finest 3D scale: an
/// endless iterator (take as many frames as needed) made by [`SinGrav::animation`].
pub struct Animation<'a, R> {
    model: &'a SinGrav,
    walk: WalkConfig,
    rng: R,
    /// The first frame's noise z(1), per 3D scale.
    first: Vec<Tensor>,
    /// z(t-1) and z(t): the walk's momentum is their difference.
    previous: Vec<Tensor>,
    current: Vec<Tensor>,
    /// Whether the first frame was returned (the walk steps before every later one).
    started: bool,
}

impl SinGrav {
    /// An animation whose noise at scales from `walk.first_moving_scale` on follows the paper's
    /// smoothed random walk `z(t+1) = a z(1) + (1 - a) (z(t) + d(t+1))`,
    /// `d(t+1) = x (z(t) - z(t-1)) + (1 - x) mu(t+1)`, with fresh noise `mu` of each scale's
    /// amplitude drawn from `rng`; coarser scales keep `z(1)`. The first frame is a sample as
    /// [`SinGrav::generate`] makes it from `z(1)`, which is the reconstruction's noise below
    /// `walk.vary_from`.
    pub fn animation<R: rand::Rng>(
        &self,
        walk: WalkConfig,
        mut rng: R,
    ) -> Result<Animation<'_, R>> {
        walk.validate(self.volume_scales())?;
        let first = self.draw_noise_from(self.volume_scales(), walk.vary_from, &mut rng)?;
        Ok(Animation {
            model: self,
            walk,
            rng,
            previous: first.clone(),
            current: first.clone(),
            first,
            started: false,
        })
    }

    /// The first `frames` frames of [`SinGrav::animation`].
    pub fn animate(
        &self,
        frames: usize,
        walk: WalkConfig,
        rng: &mut impl rand::Rng,
    ) -> Result<Vec<Tensor>> {
        self.animation(walk, rng)?.take(frames).collect()
    }
}

impl<R: rand::Rng> Animation<'_, R> {
    /// Returns the next frame's raw volume `(1, 4, s, s, s)` (detached).
    pub fn next_frame(&mut self) -> Result<Tensor> {
        if self.started {
            self.step()?;
        }
        self.started = true;
        Ok(self.model.generate(&self.current)?.detach())
    }

    /// Moves past the next `frames` frames without generating them: the next
    /// [`Animation::next_frame`] returns what it would have returned after `frames` calls (a
    /// viewer's slider jumps to frame t at the cost of t noise draws, not t generations).
    ///
    /// ```
    /// use rand::SeedableRng;
    /// use singrav::applications::WalkConfig;
    /// let config = singrav::TrainConfig::preset("micro")?;
    /// let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0);
    /// let mut model = singrav::SinGrav::new(&config, &candle_core::Device::Cpu, &mut rng)?;
    /// model.push_generator(1.0, &mut rng)?;
    /// model.push_generator(0.5, &mut rng)?;
    /// let rng = || rand_chacha::ChaCha8Rng::seed_from_u64(3);
    /// let third = model.animation(WalkConfig::default(), rng())?.nth(3).unwrap()?;
    /// let mut walk = model.animation(WalkConfig::default(), rng())?;
    /// walk.skip_frames(3)?;
    /// let skipped = walk.next_frame()?;
    /// assert_eq!((third - skipped)?.abs()?.max_all()?.to_scalar::<f32>()?, 0.0);
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    pub fn skip_frames(&mut self, frames: usize) -> Result<()> {
        for _ in 0..frames {
            if self.started {
                self.step()?;
            }
            self.started = true;
        }
        Ok(())
    }

    /// Moves the noise one step along the walk.
    fn step(&mut self) -> Result<()> {
        let scales = self.current.len();
        let mu = self.model.draw_noise(scales, &mut self.rng)?;
        let (a, x) = (self.walk.anchor, self.walk.momentum);
        let mut next = self.current.clone();
        let first_moving = self.walk.first_moving_scale.max(self.walk.vary_from);
        for i in first_moving - 1..scales {
            let step = ((&self.current[i] - &self.previous[i])? * x + (&mu[i] * (1.0 - x))?)?;
            next[i] = ((&self.first[i] * a)? + ((&self.current[i] + step)? * (1.0 - a))?)?;
        }
        self.previous = std::mem::replace(&mut self.current, next);
        Ok(())
    }
}

impl<R: rand::Rng> Iterator for Animation<'_, R> {
    type Item = Result<Tensor>;

    fn next(&mut self) -> Option<Self::Item> {
        Some(self.next_frame())
    }
}

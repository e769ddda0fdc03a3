//! The grid a fit optimises: raw (pre-activation) values, their Adam moments and the mask of
//! live voxels, with a fused activation, backward and Adam update in one pass over the voxels.
//!
//! Candle's tensor ops would take a dozen passes (and allocations) over the grid per step for
//! the activation, its gradient, total variation and Adam; the fit's grids are plain arrays, so
//! each of those is one parallel loop here and only the renderer goes through candle.

use radiance_volume::{resample_tensor, Activation, GridDims};
use rayon::prelude::*;

use crate::error::Result;
use radiance_volume::dilate_mask;

/// Adam's decay rates and epsilon (PyTorch's defaults).
const BETA1: f32 = 0.9;
const BETA2: f32 = 0.999;
const ADAM_EPS: f32 = 1e-8;
/// Voxels per unit of parallel work.
const CHUNK: usize = 4096;

/// Channels of a fitted grid: density, red, green, blue.
pub(super) const CHANNELS: usize = 4;

/// A raw `(4, s, s, s)` grid under optimisation (planar: channel, z, y, x).
#[derive(Debug, Clone)]
pub(super) struct FitGrid {
    size: usize,
    raw: Vec<f32>,
    first_moment: Vec<f32>,
    second_moment: Vec<f32>,
    /// Adam steps since the moments were last reset (at every growth).
    adam_steps: i32,
    /// Per voxel (z, y, x): whether its density is rendered; dead voxels render as exactly
    /// empty (so the renderer skips them) and are not updated.
    live: Vec<bool>,
    /// How many entries of `live` are set (kept so progress reports need no count per step).
    live_count: usize,
    activation: Activation,
    /// Whether the renderer takes raw density and activates it per sample
    /// (volrender's `DensityInterpolation::PostActivated`) instead of physical voxels.
    post_activated: bool,
}

/// The raw density a dead voxel renders with when the renderer activates density per sample:
/// far enough below the activation's knee that its softplus is exactly 0 in f32 (so the
/// renderer skips it, as it skips a dead voxel's physical 0).
const DEAD_RAW_DENSITY: f32 = -1.0e4;

/// Weights of the regularisers, applied to raw values, each a mean over voxels.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Regularisers {
    /// Total variation (squared differences to the 6 neighbours) of raw density.
    pub tv_density: f32,
    /// Total variation of raw colour.
    pub tv_colour: f32,
}

/// `ln(1 + e^x)` without overflow.
fn softplus(x: f32) -> f32 {
    x.max(0.0) + (-x.abs()).exp().ln_1p()
}

fn sigmoid(x: f32) -> f32 {
    1.0 / (1.0 + (-x).exp())
}

impl FitGrid {
    /// A grid of edge `size` with density `initial_sigma` (physical, per world length) and grey
    /// colour everywhere, every voxel live.
    /// With `post_activated` the renderer activates density per sample ([`FitGrid::rendered`]).
    pub(super) fn new(
        size: usize,
        activation: Activation,
        initial_sigma: f32,
        post_activated: bool,
    ) -> Result<Self> {
        let voxels = size * size * size;
        let mut raw = vec![0.0; CHANNELS * voxels];
        raw[..voxels].fill(activation.raw_density(initial_sigma)?);
        Ok(Self::from_raw(size, raw, activation).post_activated(post_activated))
    }

    /// The same grid, rendered with per-sample activation of its density or not.
    pub(super) fn post_activated(self, post_activated: bool) -> Self {
        Self {
            post_activated,
            ..self
        }
    }

    /// A grid of edge `size` holding the raw values `raw` (planar `(4, s, s, s)`), fresh Adam
    /// moments, every voxel live.
    pub(super) fn from_raw(size: usize, raw: Vec<f32>, activation: Activation) -> Self {
        let voxels = size * size * size;
        Self {
            size,
            first_moment: vec![0.0; raw.len()],
            second_moment: vec![0.0; raw.len()],
            raw,
            adam_steps: 0,
            live: vec![true; voxels],
            live_count: voxels,
            activation,
            post_activated: false,
        }
    }

    /// The raw values, planar `(4, s, s, s)`, without the grid's optimiser state.
    pub(super) fn into_raw(self) -> Vec<f32> {
        self.raw
    }

    /// The grid's edge in voxels.
    pub(super) fn size(&self) -> usize {
        self.size
    }

    fn voxels(&self) -> usize {
        self.size * self.size * self.size
    }

    /// The fraction of voxels that are live.
    pub(super) fn live_fraction(&self) -> f32 {
        self.live_count as f32 / self.voxels() as f32
    }

    /// The physical `(4, s, s, s)` values: `sigma = scale softplus(raw + shift)` on live voxels
    /// and 0 on dead ones, `rgb = sigmoid(raw)`.
    pub(super) fn physical(&self) -> Vec<f32> {
        self.values(true)
    }

    /// The `(4, s, s, s)` values the fit's renderer takes: [`FitGrid::physical`], or when
    /// post-activated the raw density itself on live voxels ([`DEAD_RAW_DENSITY`] on dead ones)
    /// beside the physical colours.
    pub(super) fn rendered(&self) -> Vec<f32> {
        self.values(!self.post_activated)
    }

    /// Colour through its activation, density through it when `activate_density`.
    fn values(&self, activate_density: bool) -> Vec<f32> {
        let voxels = self.voxels();
        let (scale, shift) = (self.activation.density_scale, self.activation.density_shift);
        let mut out = vec![0.0; self.raw.len()];
        let (density, colour) = out.split_at_mut(voxels);
        density
            .par_chunks_mut(CHUNK)
            .zip(self.raw[..voxels].par_chunks(CHUNK))
            .zip(self.live.par_chunks(CHUNK))
            .for_each(|((out, raw), live)| {
                for ((o, &r), &l) in out.iter_mut().zip(raw).zip(live) {
                    *o = match (l, activate_density) {
                        (true, true) => scale * softplus(r + shift),
                        (true, false) => r,
                        (false, true) => 0.0,
                        (false, false) => DEAD_RAW_DENSITY,
                    };
                }
            });
        colour
            .par_chunks_mut(CHUNK)
            .zip(self.raw[voxels..].par_chunks(CHUNK))
            .for_each(|(out, raw)| {
                for (o, &r) in out.iter_mut().zip(raw) {
                    *o = sigmoid(r);
                }
            });
        out
    }

    /// Turns `grad`, the loss gradient with respect to [`FitGrid::rendered`], into the gradient
    /// with respect to the raw values (the activation's chain rule, which for post-activated
    /// density the renderer has already applied; 0 on dead densities), in place, and adds the
    /// regularisers' gradients.
    pub(super) fn raw_gradient(&self, grad: &mut [f32], regularisers: &Regularisers) {
        let voxels = self.voxels();
        let (scale, shift) = (self.activation.density_scale, self.activation.density_shift);
        let post_activated = self.post_activated;
        let (density, colour) = grad.split_at_mut(voxels);
        density
            .par_chunks_mut(CHUNK)
            .zip(self.raw[..voxels].par_chunks(CHUNK))
            .zip(self.live.par_chunks(CHUNK))
            .for_each(|((g, raw), live)| {
                for ((g, &r), &l) in g.iter_mut().zip(raw).zip(live) {
                    // d softplus(x) / dx = sigmoid(x).
                    *g = match (l, post_activated) {
                        (true, false) => *g * scale * sigmoid(r + shift),
                        (true, true) => *g,
                        (false, _) => 0.0,
                    };
                }
            });
        colour
            .par_chunks_mut(CHUNK)
            .zip(self.raw[voxels..].par_chunks(CHUNK))
            .for_each(|(g, raw)| {
                for (g, &r) in g.iter_mut().zip(raw) {
                    let c = sigmoid(r);
                    *g *= c * (1.0 - c);
                }
            });
        for channel in 0..CHANNELS {
            let weight = if channel == 0 {
                regularisers.tv_density
            } else {
                regularisers.tv_colour
            };
            if weight > 0.0 {
                let range = channel * voxels..(channel + 1) * voxels;
                add_tv_gradient(
                    &self.raw[range.clone()],
                    &mut grad[range],
                    self.size,
                    weight,
                );
            }
        }
    }

    /// One Adam step with learning rate `lr` along the raw gradient `grad`; dead densities keep
    /// their values and moments.
    pub(super) fn adam_step(&mut self, grad: &[f32], lr: f32) {
        self.adam_steps += 1;
        let t = self.adam_steps;
        let step_size = lr / (1.0 - BETA1.powi(t));
        let second_correction = 1.0 - BETA2.powi(t);
        let voxels = self.voxels();
        let live = &self.live;
        self.raw
            .par_chunks_mut(CHUNK)
            .zip(self.first_moment.par_chunks_mut(CHUNK))
            .zip(self.second_moment.par_chunks_mut(CHUNK))
            .zip(grad.par_chunks(CHUNK))
            .enumerate()
            .for_each(|(chunk, (((raw, m), v), g))| {
                let start = chunk * CHUNK;
                for i in 0..raw.len() {
                    let index = start + i;
                    if index < voxels && !live[index] {
                        continue;
                    }
                    m[i] = BETA1 * m[i] + (1.0 - BETA1) * g[i];
                    v[i] = BETA2 * v[i] + (1.0 - BETA2) * g[i] * g[i];
                    raw[i] -= step_size * m[i] / ((v[i] / second_correction).sqrt() + ADAM_EPS);
                }
            });
    }

    /// Marks as live the voxels within one voxel (a 3x3x3 block) of a voxel whose opacity
    /// across its own width, `1 - exp(-sigma * voxel)`, reaches `threshold`; the rest die.
    /// Judged from the raw values, so a voxel killed earlier revives when a neighbour grows.
    pub(super) fn refresh_live(&mut self, threshold: f32, voxel_length: f32) -> Result<()> {
        let s = self.size;
        let voxels = self.voxels();
        let (scale, shift) = (self.activation.density_scale, self.activation.density_shift);
        // sigma >= threshold_sigma  <=>  1 - exp(-sigma * voxel) >= threshold.
        let threshold_sigma = -(1.0 - threshold).ln() / voxel_length;
        let dense: Vec<bool> = self.raw[..voxels]
            .par_iter()
            .map(|&r| scale * softplus(r + shift) >= threshold_sigma)
            .collect();
        self.live = dilate_mask(&dense, [s, s, s], 1)?;
        self.live_count = self.live.iter().filter(|&&l| l).count();
        Ok(())
    }

    /// Resamples the raw grid to edge `size` (trilinear, cell-centred) and resets the Adam
    /// moments; every voxel starts live.
    pub(super) fn grow(&mut self, size: usize) -> Result<()> {
        let s = self.size;
        let raw = candle_core::Tensor::from_slice(
            &self.raw,
            (CHANNELS, s, s, s),
            &candle_core::Device::Cpu,
        )?;
        let grown = resample_tensor(&raw, GridDims::cube(size))?;
        *self = Self::from_raw(size, grown.flatten_all()?.to_vec1()?, self.activation)
            .post_activated(self.post_activated);
        Ok(())
    }
}

/// Adds to `grad` the gradient of total variation over an `s^3` grid: `weight / s^3` times the
/// sum over pairs of face neighbours (each pair once) of `(x_v - x_n)^2`.
fn add_tv_gradient(x: &[f32], grad: &mut [f32], s: usize, weight: f32) {
    let norm = weight / x.len() as f32;
    let plane = s * s;
    grad.par_chunks_mut(plane)
        .enumerate()
        .for_each(|(z, grad_plane)| {
            for y in 0..s {
                for xi in 0..s {
                    let i = z * plane + y * s + xi;
                    let centre = x[i];
                    let mut sum = 0.0;
                    let mut neighbour = |j: usize| sum += centre - x[j];
                    if xi > 0 {
                        neighbour(i - 1);
                    }
                    if xi + 1 < s {
                        neighbour(i + 1);
                    }
                    if y > 0 {
                        neighbour(i - s);
                    }
                    if y + 1 < s {
                        neighbour(i + s);
                    }
                    if z > 0 {
                        neighbour(i - plane);
                    }
                    if z + 1 < s {
                        neighbour(i + plane);
                    }
                    grad_plane[y * s + xi] += 2.0 * norm * sum;
                }
            }
        });
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::{Device, Tensor, Var};

    fn activation() -> Activation {
        Activation::default()
            .with_density_scale(25.0)
            .with_density_shift(-4.0)
    }

    fn random_grid(size: usize, seed: u64) -> FitGrid {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let raw = (0..CHANNELS * size * size * size)
            .map(|_| rng.random_range(-6.0f32..6.0))
            .collect();
        FitGrid::from_raw(size, raw, activation())
    }

    #[test]
    fn physical_matches_the_activation() -> Result<()> {
        let grid = random_grid(5, 1);
        let raw = Tensor::from_slice(&grid.raw, (4, 5, 5, 5), &Device::Cpu)?;
        let want: Vec<f32> = activation().apply(&raw)?.flatten_all()?.to_vec1()?;
        for (a, b) in grid.physical().iter().zip(&want) {
            assert!((a - b).abs() <= 1e-5 * b.abs().max(1.0), "{a} vs {b}");
        }
        Ok(())
    }

    #[test]
    fn raw_gradient_matches_candle_autodiff() -> Result<()> {
        let grid = random_grid(4, 2);
        let upstream: Vec<f32> = random_grid(4, 3).raw.iter().map(|x| x / 6.0).collect();
        let raw = Var::from_slice(&grid.raw, (4, 4, 4, 4), &Device::Cpu)?;
        let up = Tensor::from_slice(&upstream, (4, 4, 4, 4), &Device::Cpu)?;
        let loss = (activation().apply(raw.as_tensor())? * up)?.sum_all()?;
        let want: Vec<f32> = loss
            .backward()?
            .get(&raw)
            .unwrap()
            .flatten_all()?
            .to_vec1()?;
        let mut got = upstream.clone();
        let none = Regularisers {
            tv_density: 0.0,
            tv_colour: 0.0,
        };
        grid.raw_gradient(&mut got, &none);
        for (a, b) in got.iter().zip(&want) {
            // Candle differentiates softplus through relu, abs, exp and log: f32 rounding.
            assert!((a - b).abs() <= 1e-4 * b.abs().max(1e-3), "{a} vs {b}");
        }
        Ok(())
    }

    #[test]
    fn tv_gradient_matches_finite_differences() {
        let s = 4;
        let x: Vec<f32> = random_grid(s, 4).raw[..s * s * s].to_vec();
        let tv = |x: &[f32]| -> f64 {
            let mut sum = 0.0f64;
            for z in 0..s {
                for y in 0..s {
                    for xi in 0..s {
                        let i = (z * s + y) * s + xi;
                        for (ok, j) in [
                            (xi + 1 < s, i + 1),
                            (y + 1 < s, i + s),
                            (z + 1 < s, i + s * s),
                        ] {
                            if ok {
                                sum += f64::from(x[i] - x[j]).powi(2);
                            }
                        }
                    }
                }
            }
            0.7 * sum / x.len() as f64
        };
        let mut grad = vec![0.0; x.len()];
        add_tv_gradient(&x, &mut grad, s, 0.7);
        let h = 1e-2f32;
        for i in [0, 5, 21, 63] {
            let (mut up, mut down) = (x.clone(), x.clone());
            up[i] += h;
            down[i] -= h;
            let numeric = (tv(&up) - tv(&down)) / (2.0 * f64::from(h));
            assert!(
                (f64::from(grad[i]) - numeric).abs() < 1e-3,
                "{i}: {} vs {numeric}",
                grad[i]
            );
        }
    }

    #[test]
    fn dilation_reaches_one_voxel_around() {
        let s = 5;
        let mut mask = vec![false; s * s * s];
        mask[(2 * s + 2) * s + 2] = true;
        let out = dilate_mask(&mask, [s, s, s], 1).unwrap();
        assert_eq!(out.iter().filter(|&&m| m).count(), 27);
        assert!(out[(s + 1) * s + 1] && out[(3 * s + 3) * s + 3] && !out[0]);
    }

    #[test]
    fn refresh_kills_empty_voxels_and_keeps_their_neighbours() -> Result<()> {
        let s = 6;
        let mut grid = FitGrid::new(s, activation(), 1e-3, false)?;
        let dense = activation().raw_density(50.0)?;
        grid.raw[(3 * s + 3) * s + 3] = dense;
        grid.refresh_live(0.01, 2.0 / s as f32)?;
        assert_eq!(grid.live.iter().filter(|&&l| l).count(), 27);
        let physical = grid.physical();
        assert_eq!(physical[0], 0.0);
        assert!((physical[(3 * s + 3) * s + 3] - 50.0).abs() < 1e-3);
        Ok(())
    }

    #[test]
    fn adam_skips_dead_densities_and_moves_the_rest() -> Result<()> {
        let s = 3;
        let mut grid = FitGrid::new(s, activation(), 1.0, false)?;
        grid.live[0] = false;
        let before = grid.raw.clone();
        grid.adam_step(&vec![1.0; grid.raw.len()], 0.1);
        assert_eq!(grid.raw[0], before[0]);
        // The first Adam step moves every parameter by lr against the gradient's sign.
        assert!((grid.raw[1] - (before[1] - 0.1)).abs() < 1e-5);
        assert!((grid.raw[s * s * s] - (before[s * s * s] - 0.1)).abs() < 1e-5);
        Ok(())
    }
}

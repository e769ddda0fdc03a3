//! Seeded randomness: one RNG per (seed, scale, iteration), so a resumed run draws exactly what
//! an uninterrupted one would, and Gaussian noise volumes drawn from it.

use candle_core::{Device, Tensor};
use radiance_volume::GridDims;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

use crate::error::Result;

/// The RNG of one training iteration (or, with `iteration = usize::MAX`, of a scale's set-up).
///
/// ```
/// use rand::Rng;
/// let a = singrav::noise::step_rng(7, 2, 10).random::<u64>();
/// assert_eq!(a, singrav::noise::step_rng(7, 2, 10).random::<u64>());
/// assert_ne!(a, singrav::noise::step_rng(7, 2, 11).random::<u64>());
/// ```
pub fn step_rng(seed: u64, scale: usize, iteration: usize) -> ChaCha8Rng {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    // Streams separate the (scale, iteration) pairs without any chance of two seeds colliding.
    rng.set_stream(((scale as u64) << 40) ^ iteration as u64);
    rng
}

/// A `(1, channels, size, size, size)` volume of independent N(0, amplitude^2) values.
///
/// ```
/// use rand::SeedableRng;
/// let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0);
/// let z = singrav::noise::gaussian_volume(&mut rng, 4, 8, 0.5, &candle_core::Device::Cpu)?;
/// assert_eq!(z.dims(), &[1, 4, 8, 8, 8]);
/// # Ok::<(), singrav::Error>(())
/// ```
pub fn gaussian_volume(
    rng: &mut impl rand::Rng,
    channels: usize,
    size: usize,
    amplitude: f64,
    device: &Device,
) -> Result<Tensor> {
    gaussian_grid(rng, channels, GridDims::cube(size), amplitude, device)
}

/// A `(1, channels, D, H, W)` volume of independent N(0, amplitude^2) values over `dims`,
/// drawn in the tensor's order (a cube draws what [`gaussian_volume`] draws).
///
/// ```
/// use rand::SeedableRng;
/// let dims = radiance_volume::GridDims::new(2, 3, 4);
/// let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0);
/// let z = singrav::noise::gaussian_grid(&mut rng, 4, dims, 0.5, &candle_core::Device::Cpu)?;
/// assert_eq!(z.dims(), &[1, 4, 2, 3, 4]);
/// # Ok::<(), singrav::Error>(())
/// ```
pub fn gaussian_grid(
    rng: &mut impl rand::Rng,
    channels: usize,
    dims: GridDims,
    amplitude: f64,
    device: &Device,
) -> Result<Tensor> {
    let count = channels * dims.voxel_count();
    let values: Vec<f32> = (0..count)
        .map(|_| {
            let x: f64 = StandardNormal.sample(rng);
            (x * amplitude) as f32
        })
        .collect();
    Ok(Tensor::from_vec(
        values,
        (1, channels, dims.d, dims.h, dims.w),
        device,
    )?)
}

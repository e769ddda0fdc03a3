//! Sliced Wasserstein distances and texture losses on candle.
//!
//! # The distance
//!
//! Between point sets X `(N, C)` and Y `(M, C)` and K directions θ_k (the columns of a
//! [`Projections`] matrix `(C, K)`), the sliced distance is the mean over k of a 1D
//! Wasserstein distance between the projections `X θ_k` and `Y θ_k`, seen as uniform
//! empirical measures:
//!
//! - [`Metric::SquaredW2`]: `SW = (1/K) Σ_k W_2^2(Xθ_k, Yθ_k)`, the usual loss (POT's
//!   `sliced_wasserstein_distance(p=2)` is its square root);
//! - [`Metric::W1`]: `SW = (1/K) Σ_k W_1(Xθ_k, Yθ_k)`.
//!
//! Each 1D distance is computed by sorting: `W_p^p = ∫_0^1 |F_X^{-1}(q) - F_Y^{-1}(q)|^p dq`
//! with the empirical quantile step functions, integrated exactly over the merged breakpoints
//! `{i/N} ∪ {j/M}` (as POT does). For N = M this is the mean over sorted pairs; for N ≠ M
//! nothing is resampled or dropped. In one dimension with θ = 1 it is the exact Wasserstein
//! distance between the two empirical measures.
//!
//! Gradients flow through the sort (a gather) to both sets, so the distance is a loss:
//! `∂SW/∂x_i = (1/K) Σ_k 2 (x_i·θ_k - y_matched)/N θ_k` for squared W2 and N = M.
//!
//! Randomness is explicit: [`Projections::random`] and every call that draws directions takes
//! an RNG, so the same seed gives the same directions.
//!
//! # Texture loss
//!
//! [`TextureLoss`] compares images through a [`FeatureExtractor`]: [`PatchPyramid`] (weights
//! free: 7x7 patches of Laplacian or Gaussian pyramid levels) or [`Vgg19`] (torchvision's
//! VGG-19 weights from a safetensors file, the layers Heitz et al. use). Images are
//! `(B, 3, H, W)`; per-layer weights and batches are supported.
//!
//! ```
//! use candle_core::{Device, Tensor};
//! use rand::SeedableRng;
//! use swd_loss::{sliced_wasserstein, Metric, Projections};
//!
//! let dev = Device::Cpu;
//! let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
//! let x = candle_core::Var::from_tensor(&Tensor::randn(0f32, 1.0, (100, 8), &dev)?)?;
//! let y = Tensor::randn(0.5f32, 1.0, (80, 8), &dev)?;
//! let p = Projections::random(8, 32, &mut rng, &dev)?;
//! let loss = sliced_wasserstein(x.as_tensor(), &y, &p, Metric::SquaredW2)?;
//! let grads = loss.backward()?;
//! assert_eq!(grads.get(x.as_tensor()).unwrap().dims(), &[100, 8]);
//! # Ok::<(), swd_loss::Error>(())
//! ```

#![forbid(unsafe_code)]
#![warn(missing_docs)]

mod error;
mod projections;
mod quantile;
mod sliced;
mod sort;
mod texture;

pub use error::{Error, Result};
pub use projections::Projections;
pub use sliced::{
    sliced_wasserstein, sliced_wasserstein_per_projection, sliced_wasserstein_resampled, Metric,
};
pub use texture::{
    FeatureExtractor, FeatureMap, Padding, PatchPyramid, PatchPyramidConfig, Points, Pooling,
    PyramidKind, Slices, TextureLoss, TextureLossConfig, TextureTarget, Vgg19, Vgg19Config,
    VggLayer,
};

/// The main types, for `use swd_loss::prelude::*`.
pub mod prelude {
    pub use crate::{sliced_wasserstein, Metric, PatchPyramid, Projections, TextureLoss, Vgg19};
}

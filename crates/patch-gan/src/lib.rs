//! The networks of SinGRAV on candle: a 3D convolution, the 3D generator, the 2D patch
//! discriminator (and its 3D twin over volumes), the final 2D upsampler, and WGAN-GP losses.
//!
//! candle has no 3D convolution; [`Conv3d`] (and [`functional::conv3d`]) fills that gap on the CPU
//! with a chunked im2col + `gemm` kernel (Winograd F(2, 3) / F(4, 3) for 3-tap kernels of 16 or
//! more input channels) and a backward pass for the input and the weight. The same kernels run
//! [`Conv2d`] ([`functional::conv2d`]), which the critics and the upsampler use: faster than
//! candle's CPU conv2d, and differentiable to any order (the gradient penalty).
//!
//! The kernels themselves, and the fused BatchNorm / LeakyReLU loops, are the `conv-kernels`
//! crate's safe functions over plain slices: all of their `unsafe` code (SIMD, raw-pointer
//! matrix products, uninitialised output buffers) lives there, under its stated policy, and this
//! crate forbids `unsafe` code. It holds the candle custom ops around them, the layers, the
//! networks and the losses.
//! [`active`] runs a generator on the active sites of its volumes only (submanifold
//! convolutions, [`Generator3d::forward_residual_active`]), at a cost in proportion to them.
//!
//! Conventions:
//! - Volumes are `(N, C, D, H, W)` (D along z, H along y, W along x), images `(N, C, H, W)`.
//! - Layers follow PyTorch: Conv3d weights are `(C_out, C_in, k, k, k)` named `weight` and `bias`,
//!   BatchNorm3d tensors `weight`, `bias`, `running_mean`, `running_var`, so a PyTorch state dict
//!   saved as safetensors loads through `VarBuilder::from_mmaped_safetensors`. New weights use
//!   PyTorch's default init (uniform in `±1/sqrt(fan_in)` for conv weights and biases).
//! - Networks are built from `vb.pp(..)` per sub-layer, so checkpoint names are stable
//!   (`blocks.{i}.conv.weight`, `blocks.{i}.bn.running_mean`, `tail.bias`, ...).
//! - Layers with batch norm implement `ModuleT` (`train = true` uses batch statistics and updates
//!   the running ones); the others implement `Module`.
//! - Losses are plain functions; randomness comes from a caller's RNG. The patch critic
//!   ([`PatchDiscriminator2d`] of images, [`PatchDiscriminator3d`] of volumes) also has its own
//!   [`PatchDiscriminator::critic_loss`] (real and fake in one forward pass) and
//!   [`PatchDiscriminator::gradient_penalty`] (the WGAN-GP penalty as a first-order graph,
//!   about twice as fast as the generic [`gradient_penalty`] and without candle's
//!   `CANDLE_GRAD_DO_NOT_DETACH`).
//!
//! Speed needs no setup call and no process-wide setting: each op enters rayon's global pool
//! once (its kernels' parallel loops then need no hand-over from the calling thread), the
//! kernels reuse their large buffers from one step to the next instead of relying on the
//! allocator's settings, and a critic's loss and penalty, and a generator's training-mode
//! layers, are one op each way, so candle's own element-wise pool has little left to do. The
//! crate's README has its speed against PyTorch and the command that measures it.
//!
//! ```
//! use candle_core::{DType, Device, Module, ModuleT, Tensor};
//! use candle_nn::{VarBuilder, VarMap};
//! use patch_gan::*;
//! let dev = Device::Cpu;
//! let varmap = VarMap::new();
//! let vb = VarBuilder::from_varmap(&varmap, DType::F32, &dev);
//! // G_1 turns noise + CSG grid (3 channels) into a raw (sigma, RGB) volume.
//! let g1 = Generator3d::new(&Generator3dConfig::for_scale(1, 5), vb.pp("g1"))?;
//! let volume = g1.forward_t(&Tensor::randn(0f32, 1., (1, 3, 8, 8, 8), &dev)?, true)?;
//! assert_eq!(volume.dims(), &[1, 4, 8, 8, 8]);
//! // D_1 scores RGB + depth renderings patch by patch.
//! let d1 = PatchDiscriminator2d::new(&PatchDiscriminator2dConfig::default(), vb.pp("d1"))?;
//! let scores = d1.forward(&Tensor::randn(0f32, 1., (1, 4, 16, 16), &dev)?)?;
//! assert_eq!(scores.dims(), &[1, 1, 6, 6]);
//! let loss = generator_loss(&scores)?;
//! # let _ = loss;
//! # Ok::<(), patch_gan::Error>(())
//! ```

#![forbid(unsafe_code)]

pub mod active;
mod conv;
mod discriminator;
mod error;
mod fused;
mod generator;
mod init;
mod norm;
mod pool;
mod storage;
mod upsampler;
mod wgan;

/// Stateless ops, named after `torch.nn.functional`.
pub mod functional {
    pub use crate::conv::op::{conv2d, conv3d, conv3d_active, conv3d_by_slices};
}

pub use active::ActiveSites;
pub use conv::{conv2d, conv3d, conv3d_no_bias, Conv, Conv2d, Conv3d, ConvConfig};
pub use discriminator::{
    receptive_field, PatchDiscriminator, PatchDiscriminator2d, PatchDiscriminator2dConfig,
    PatchDiscriminator3d, PatchDiscriminatorConfig,
};
pub use error::{Error, Result};
pub use fused::bias_leaky_relu;
pub use generator::{Generator3d, Generator3dConfig};
pub use norm::{batch_norm3d, leaky_relu, BatchNorm3d, InstanceNorm2d, LEAKY_SLOPE, NORM_EPS};
pub use upsampler::{upsample_bilinear2x, Upsampler2d, Upsampler2dConfig};
pub use wgan::{critic_loss, generator_loss, gradient_penalty, GradientNorm, GradientPenalty};

/// The types most users of this crate need, for `use patch_gan::prelude::*;`.
pub mod prelude {
    pub use crate::{
        Conv2d, Conv3d, ConvConfig, Generator3d, Generator3dConfig, PatchDiscriminator,
        PatchDiscriminator2d, PatchDiscriminator3d, Upsampler2d,
    };
}

/// The README's example, run as a doctest.
#[doc = include_str!("../README.md")]
#[cfg(doctest)]
struct ReadmeExample;

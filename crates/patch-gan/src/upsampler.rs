//! `Upsampler2d`: the paper's final-scale 2D generator G_N, doubling the last rendering.

use candle_core::{Module, Tensor};
use candle_nn::VarBuilder;

use crate::conv::{conv2d, Conv2d, ConvConfig};
use crate::error::{invalid, Result};
use crate::norm::{leaky_relu, InstanceNorm2d, LEAKY_SLOPE};

/// Shape of an [`Upsampler2d`]; the default is the paper's table "G_N": 3 image channels and
/// widths 32, 16, 8, 8.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Upsampler2dConfig {
    /// Image channels in and out (3, RGB).
    pub channels: usize,
    /// Widths of the feature maps: the upsampling layer's output, then each block's output.
    pub widths: [usize; 4],
}

impl Default for Upsampler2dConfig {
    fn default() -> Self {
        Self {
            channels: 3,
            widths: [32, 16, 8, 8],
        }
    }
}

/// G_N: `(N, C, H, W)` -> `(N, C, 2H, 2W)`.
///
/// 1. Upsampling layer, after StyleNeRF: a learned 3x3 conv to `4 widths[0]` channels,
///    pixel-shuffled to `widths[0]` channels at twice the resolution (sub-pixel convolution), then
///    a fixed 3x3 binomial blur (`[1 2 1]^T [1 2 1] / 16`, edge-replicated) against checkerboard
///    artefacts. StyleNeRF also adds the nearest-upsampled input before the shuffle; with 3 input
///    and 32 output channels that sum has no channel-wise meaning, so the naive upsample enters
///    through the final residual instead.
/// 2. Three blocks of 3x3 Conv2d (padding 1) + InstanceNorm2d + LeakyReLU(0.2):
///    32 -> 16 -> 8 -> 8 channels.
/// 3. A 3x3 Conv2d 8 -> 3, added to the bilinear x2 upsample of the input
///    ([`upsample_bilinear2x`], the paper's `x_{N-1} up`).
///
/// Checkpoint names: `up.{weight,bias}`, `blocks.{i}.conv.{weight,bias}` (i = 0, 1, 2),
/// `tail.{weight,bias}`.
///
/// ```
/// use candle_core::{DType, Device, Module, Tensor};
/// use candle_nn::{VarBuilder, VarMap};
/// use patch_gan::{Upsampler2d, Upsampler2dConfig};
/// let varmap = VarMap::new();
/// let vb = VarBuilder::from_varmap(&varmap, DType::F32, &Device::Cpu);
/// let g = Upsampler2d::new(&Upsampler2dConfig::default(), vb.pp("gN"))?;
/// let y = g.forward(&Tensor::zeros((1, 3, 16, 16), DType::F32, &Device::Cpu)?)?;
/// assert_eq!(y.dims(), &[1, 3, 32, 32]);
/// # Ok::<(), patch_gan::Error>(())
/// ```
#[derive(Debug, Clone)]
pub struct Upsampler2d {
    up: Conv2d,
    blocks: Vec<Conv2d>,
    tail: Conv2d,
    norm: InstanceNorm2d,
}

/// Factor of the upsampling layer.
const SCALE: usize = 2;

impl Upsampler2d {
    /// Builds (or loads) the upsampler's tensors under `vb`.
    pub fn new(config: &Upsampler2dConfig, vb: VarBuilder) -> Result<Self> {
        if config.channels == 0 || config.widths.contains(&0) {
            return Err(invalid("Upsampler2d channels", "must be positive"));
        }
        let [w0, ..] = config.widths;
        let same = ConvConfig::default().with_padding(1);
        let up = conv2d(config.channels, SCALE * SCALE * w0, 3, same, vb.pp("up"))?;
        let blocks = config
            .widths
            .windows(2)
            .enumerate()
            .map(|(i, w)| conv2d(w[0], w[1], 3, same, vb.pp("blocks").pp(i).pp("conv")))
            .collect::<Result<Vec<_>>>()?;
        let tail = conv2d(config.widths[3], config.channels, 3, same, vb.pp("tail"))?;
        Ok(Self {
            up,
            blocks,
            tail,
            norm: InstanceNorm2d::default(),
        })
    }
}

impl Module for Upsampler2d {
    fn forward(&self, xs: &Tensor) -> candle_core::Result<Tensor> {
        let features = candle_nn::ops::pixel_shuffle(&self.up.forward(xs)?, SCALE)?;
        let mut h = blur(&features)?;
        for conv in &self.blocks {
            h = leaky_relu(&self.norm.forward(&conv.forward(&h)?)?, LEAKY_SLOPE)?;
        }
        self.tail.forward(&h)? + upsample_bilinear2x(xs)?
    }
}

/// The fixed 3x3 binomial blur of every channel, replicating edge pixels.
fn blur(xs: &Tensor) -> candle_core::Result<Tensor> {
    let (n, c, h, w) = xs.dims4()?;
    let taps = [1.0, 2.0, 1.0];
    let kernel: Vec<f64> = taps
        .iter()
        .flat_map(|a| taps.iter().map(move |b| a * b / 16.0))
        .collect();
    let kernel = Tensor::from_vec(kernel, (1, 1, 3, 3), xs.device())?.to_dtype(xs.dtype())?;
    // Channels go into the batch so one single-channel conv blurs all of them independently.
    xs.reshape((n * c, 1, h, w))?
        .pad_with_same(2, 1, 1)?
        .pad_with_same(3, 1, 1)?
        .conv2d(&kernel, 0, 1, 1, 1)?
        .reshape((n, c, h, w))
}

/// Bilinear x2 upsampling of `(N, C, H, W)` with PyTorch's `align_corners = false` (half-pixel
/// centres, edges clamped), built from differentiable ops; candle's `upsample_bilinear2d` has no
/// backward pass.
///
/// ```
/// use candle_core::{Device, Tensor};
/// let x = Tensor::new(&[[[[0f32, 4.]]]], &Device::Cpu)?;
/// let y = patch_gan::upsample_bilinear2x(&x)?;
/// assert_eq!(y.flatten_all()?.to_vec1::<f32>()?, [0., 1., 3., 4., 0., 1., 3., 4.]);
/// # Ok::<(), candle_core::Error>(())
/// ```
pub fn upsample_bilinear2x(xs: &Tensor) -> candle_core::Result<Tensor> {
    upsample_axis2x(&upsample_axis2x(xs, 2)?, 3)
}

/// Doubles axis `dim`: output `2i` is `3/4 x[i] + 1/4 x[i-1]`, output `2i+1` is
/// `3/4 x[i] + 1/4 x[i+1]`, with indices clamped to the axis.
fn upsample_axis2x(xs: &Tensor, dim: usize) -> candle_core::Result<Tensor> {
    let n = xs.dim(dim)?;
    let first = xs.narrow(dim, 0, 1)?;
    let last = xs.narrow(dim, n - 1, 1)?;
    let prev = Tensor::cat(&[&first, &xs.narrow(dim, 0, n - 1)?], dim)?;
    let next = Tensor::cat(&[&xs.narrow(dim, 1, n - 1)?, &last], dim)?;
    let even = ((xs * 0.75)? + (prev * 0.25)?)?;
    let odd = ((xs * 0.75)? + (next * 0.25)?)?;
    let mut dims = xs.dims().to_vec();
    dims[dim] *= 2;
    Tensor::stack(&[even, odd], dim + 1)?.reshape(dims)
}

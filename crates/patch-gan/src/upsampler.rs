//! `Upsampler2d`: the paper's final-scale 2D generator G_N, doubling the last rendering.

use candle_core::{Module, Tensor};
use candle_nn::VarBuilder;

use crate::conv::{conv2d, Conv2d, ConvConfig};
use crate::error::{invalid, Result};
use crate::norm::{InstanceNorm2d, LEAKY_SLOPE};

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
            h = self
                .norm
                .forward_activated(&conv.forward(&h)?, LEAKY_SLOPE)?;
        }
        self.tail.forward(&h)? + upsample_bilinear2x(xs)?
    }
}

/// The fixed 3x3 binomial blur of every channel, replicating edge pixels: the separable
/// `[1 2 1] / 4` along rows, then along columns. Built from shifted copies rather than a
/// convolution because candle's conv2d backward also computes the (constant) kernel's gradient,
/// a correlation with an image-sized kernel that cost more than the rest of the upsampler.
fn blur(xs: &Tensor) -> candle_core::Result<Tensor> {
    blur_axis(&blur_axis(xs, 2)?, 3)
}

/// `[1 2 1] / 4` along axis `dim`, indices clamped to the axis.
fn blur_axis(xs: &Tensor, dim: usize) -> candle_core::Result<Tensor> {
    let (prev, next) = clamped_neighbours(xs, dim)?;
    (xs * 0.5)? + ((prev + next)? * 0.25)?
}

/// `xs` shifted by one along `dim` both ways, `(x[i-1], x[i+1])`, indices clamped to the axis.
fn clamped_neighbours(xs: &Tensor, dim: usize) -> candle_core::Result<(Tensor, Tensor)> {
    let n = xs.dim(dim)?;
    let padded = xs.pad_with_same(dim, 1, 1)?;
    Ok((padded.narrow(dim, 0, n)?, padded.narrow(dim, 2, n)?))
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
    let (prev, next) = clamped_neighbours(xs, dim)?;
    let even = ((xs * 0.75)? + (prev * 0.25)?)?;
    let odd = ((xs * 0.75)? + (next * 0.25)?)?;
    let mut dims = xs.dims().to_vec();
    dims[dim] *= 2;
    Tensor::stack(&[even, odd], dim + 1)?.reshape(dims)
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::{Device, Var};

    /// The 3x3 binomial kernel in f64 with indices clamped to the image, as the `(output,
    /// source, weight)` terms of the sum (the blur gathers along them, its adjoint scatters):
    /// every pair of a row term and a column term of `[1 2 1] / 4`.
    fn direct_terms(h: usize, w: usize) -> Vec<(usize, usize, f64)> {
        let axis = |n: usize| -> Vec<(usize, usize, f64)> {
            (0..n)
                .flat_map(|i| {
                    [
                        (i.saturating_sub(1), 0.25),
                        (i, 0.5),
                        ((i + 1).min(n - 1), 0.25),
                    ]
                    .map(|(source, weight)| (i, source, weight))
                })
                .collect()
        };
        let columns = axis(w);
        axis(h)
            .into_iter()
            .flat_map(|(oi, si, ti)| {
                columns
                    .iter()
                    .map(move |&(oj, sj, tj)| (oi * w + oj, si * w + sj, ti * tj))
            })
            .collect()
    }

    /// A fixed ramp folded into [-1, 1), so the test needs no random generator.
    fn values(n: usize, salt: usize) -> Vec<f64> {
        (0..n)
            .map(|i| ((i * 13 + salt * 7) % 29) as f64 / 14.5 - 1.0)
            .collect()
    }

    fn close(got: &[f64], want: &[f64], what: &str) {
        for (g, w) in got.iter().zip(want) {
            assert!((g - w).abs() < 1e-14, "{what}: {g} vs {w}");
        }
    }

    /// Forward against the direct kernel, backward against its adjoint (the terms scattered),
    /// on sizes including single rows and columns.
    #[test]
    fn blur_and_its_gradient_equal_the_direct_kernel_with_clamped_edges() {
        for (h, w) in [(1, 1), (1, 4), (3, 1), (2, 2), (5, 7)] {
            let len = 2 * 3 * h * w;
            let x = values(len, h * 10 + w);
            let u = values(len, h * 10 + w + 1);
            let xs = Var::from_vec(x.clone(), (2, 3, h, w), &Device::Cpu).unwrap();
            let us = Tensor::from_vec(u.clone(), (2, 3, h, w), &Device::Cpu).unwrap();
            let ys = blur(xs.as_tensor()).unwrap();
            let grad = (&ys * &us).unwrap().sum_all().unwrap().backward().unwrap();
            let ours = ys.flatten_all().unwrap().to_vec1::<f64>().unwrap();
            let ours_grad = grad.get(&xs).unwrap().flatten_all().unwrap();
            let ours_grad = ours_grad.to_vec1::<f64>().unwrap();
            let plane = h * w;
            for p in 0..len / plane {
                let (mut want, mut want_grad) = (vec![0.0; plane], vec![0.0; plane]);
                for (o, s, k) in direct_terms(h, w) {
                    want[o] += k * x[p * plane + s];
                    want_grad[s] += k * u[p * plane + o];
                }
                let at = p * plane..(p + 1) * plane;
                close(&ours[at.clone()], &want, &format!("{h}x{w} blur"));
                close(&ours_grad[at], &want_grad, &format!("{h}x{w} gradient"));
            }
        }
    }
}

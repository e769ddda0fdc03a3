//! Convolutions for candle with PyTorch's weight layout, names and init: [`Conv3d`] (which candle
//! lacks) and [`Conv2d`] (faster on the CPU than candle's, and differentiable to any order), both
//! on the CPU kernels of `conv-kernels` (chunked im2col + `gemm`, and Winograd).

mod active;
mod layer;
pub(crate) mod op;
mod slices;

pub use layer::{conv2d, conv3d, conv3d_no_bias, Conv, Conv2d, Conv3d};

use candle_core::Tensor;
use candle_nn::VarBuilder;

use crate::error::{invalid, Result};
use crate::init::torch_conv_init;

/// Padding (zeros, on every side of every spatial axis) and stride of a [`Conv3d`] or [`Conv2d`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ConvConfig {
    /// Zeros added before and after each spatial axis.
    pub padding: usize,
    /// Step between outputs, at least 1.
    pub stride: usize,
}

impl Default for ConvConfig {
    fn default() -> Self {
        Self {
            padding: 0,
            stride: 1,
        }
    }
}

impl ConvConfig {
    /// The same config with `padding` zeros on every side.
    pub fn with_padding(self, padding: usize) -> Self {
        Self { padding, ..self }
    }

    /// The same config with step `stride`.
    pub fn with_stride(self, stride: usize) -> Self {
        Self { stride, ..self }
    }
}

/// Checks that `bias` (if any) is `(C_out,)` for a weight whose first axis is `C_out`.
fn check_bias(weight: &Tensor, bias: Option<&Tensor>) -> Result<()> {
    let c_out = weight.dims().first().copied().unwrap_or(0);
    match bias {
        Some(b) if b.dims() != [c_out] => Err(invalid(
            "bias",
            format!("expected ({c_out},), got {:?}", b.shape()),
        )),
        _ => Ok(()),
    }
}

/// The weight `(C_out, C_in, k, ..., k)` (`spatial_axes` kernel axes) and optional bias of a new
/// layer under `vb`, with PyTorch's default init.
pub(crate) fn layer_tensors(
    in_channels: usize,
    out_channels: usize,
    kernel: usize,
    spatial_axes: usize,
    with_bias: bool,
    vb: VarBuilder,
) -> Result<(Tensor, Option<Tensor>)> {
    if in_channels == 0 || out_channels == 0 || kernel == 0 {
        return Err(invalid(
            "conv",
            format!("channels and kernel must be positive, got {in_channels} -> {out_channels}, k = {kernel}"),
        ));
    }
    let taps = kernel.pow(spatial_axes as u32);
    let (w_init, b_init) = torch_conv_init(in_channels * taps);
    let mut shape = vec![out_channels, in_channels];
    shape.extend(std::iter::repeat_n(kernel, spatial_axes));
    let weight = vb.get_with_hints(shape, "weight", w_init)?;
    let bias = if with_bias {
        Some(vb.get_with_hints(out_channels, "bias", b_init)?)
    } else {
        None
    };
    Ok((weight, bias))
}

//! `Conv3d`: the 3D convolution layer.

use candle_core::{Module, Tensor};
use candle_nn::VarBuilder;

use super::{check_bias, layer_tensors, op, ConvConfig};
use crate::error::{invalid, Result};

/// A 3D convolution: weight `(C_out, C_in, kd, kh, kw)`, optional bias `(C_out,)`, input
/// `(N, C_in, D, H, W)`, output `(N, C_out, D_out, H_out, W_out)`.
///
/// ```
/// use candle_core::{DType, Device, Module, Tensor};
/// use candle_nn::{VarBuilder, VarMap};
/// use patch_gan::{conv3d, ConvConfig};
/// let varmap = VarMap::new();
/// let vb = VarBuilder::from_varmap(&varmap, DType::F32, &Device::Cpu);
/// let conv = conv3d(4, 8, 3, ConvConfig::default().with_padding(1), vb.pp("conv"))?;
/// let y = conv.forward(&Tensor::zeros((1, 4, 5, 6, 7), DType::F32, &Device::Cpu)?)?;
/// assert_eq!(y.dims(), &[1, 8, 5, 6, 7]);
/// # Ok::<(), patch_gan::Error>(())
/// ```
#[derive(Debug, Clone)]
pub struct Conv3d {
    weight: Tensor,
    bias: Option<Tensor>,
    config: ConvConfig,
}

impl Conv3d {
    /// A layer from ready tensors: `weight` `(C_out, C_in, kd, kh, kw)` and `bias` `(C_out,)`.
    pub fn new(weight: Tensor, bias: Option<Tensor>, config: ConvConfig) -> Result<Self> {
        if weight.rank() != 5 {
            return Err(invalid(
                "weight",
                format!(
                    "expected (C_out, C_in, kd, kh, kw), got {:?}",
                    weight.shape()
                ),
            ));
        }
        check_bias(&weight, bias.as_ref())?;
        Ok(Self {
            weight,
            bias,
            config,
        })
    }

    /// The weight, `(C_out, C_in, kd, kh, kw)`.
    pub fn weight(&self) -> &Tensor {
        &self.weight
    }

    /// The bias, `(C_out,)`, if any.
    pub fn bias(&self) -> Option<&Tensor> {
        self.bias.as_ref()
    }

    /// Padding and stride.
    pub fn config(&self) -> ConvConfig {
        self.config
    }
}

impl Module for Conv3d {
    fn forward(&self, xs: &Tensor) -> candle_core::Result<Tensor> {
        let ys = op::conv3d(xs, &self.weight, self.config)?;
        match &self.bias {
            None => Ok(ys),
            Some(b) => crate::fused::bias_add(&ys, b),
        }
    }
}

/// A [`Conv3d`] with bias and a cubic kernel whose tensors are `weight` and `bias` under `vb`, as
/// in a PyTorch `nn.Conv3d` state dict; new variables start from PyTorch's default init (uniform
/// in `±1/sqrt(C_in k^3)` for both).
pub fn conv3d(
    in_channels: usize,
    out_channels: usize,
    kernel: usize,
    config: ConvConfig,
    vb: VarBuilder,
) -> Result<Conv3d> {
    let (weight, bias) = layer_tensors(in_channels, out_channels, kernel, 3, true, vb)?;
    Conv3d::new(weight, bias, config)
}

/// Like [`conv3d`] without a bias (only `weight` is read).
pub fn conv3d_no_bias(
    in_channels: usize,
    out_channels: usize,
    kernel: usize,
    config: ConvConfig,
    vb: VarBuilder,
) -> Result<Conv3d> {
    let (weight, bias) = layer_tensors(in_channels, out_channels, kernel, 3, false, vb)?;
    Conv3d::new(weight, bias, config)
}

//! `Conv2d`: the 2D convolution layer of the critics and the upsampler.

use candle_core::{Module, Tensor};
use candle_nn::VarBuilder;

use super::{check_bias, layer_tensors, op, ConvConfig};
use crate::error::{invalid, Result};

/// A 2D convolution on [`functional::conv2d`](crate::functional::conv2d): weight
/// `(C_out, C_in, kh, kw)`, optional bias `(C_out,)`, input `(N, C_in, H, W)`, output
/// `(N, C_out, H_out, W_out)`. Unlike `candle_nn::Conv2d` its CPU backward pass is itself
/// differentiable through our kernels, which is what the gradient penalty's second-order
/// gradients run on.
///
/// ```
/// use candle_core::{DType, Device, Module, Tensor};
/// use candle_nn::{VarBuilder, VarMap};
/// use patch_gan::{conv2d, ConvConfig};
/// let varmap = VarMap::new();
/// let vb = VarBuilder::from_varmap(&varmap, DType::F32, &Device::Cpu);
/// let conv = conv2d(4, 8, 3, ConvConfig::default(), vb.pp("conv"))?;
/// let y = conv.forward(&Tensor::zeros((2, 4, 10, 12), DType::F32, &Device::Cpu)?)?;
/// assert_eq!(y.dims(), &[2, 8, 8, 10]);
/// # Ok::<(), patch_gan::Error>(())
/// ```
#[derive(Debug, Clone)]
pub struct Conv2d {
    weight: Tensor,
    bias: Option<Tensor>,
    config: ConvConfig,
}

impl Conv2d {
    /// A layer from ready tensors: `weight` `(C_out, C_in, kh, kw)` and `bias` `(C_out,)`.
    pub fn new(weight: Tensor, bias: Option<Tensor>, config: ConvConfig) -> Result<Self> {
        if weight.rank() != 4 {
            return Err(invalid(
                "weight",
                format!("expected (C_out, C_in, kh, kw), got {:?}", weight.shape()),
            ));
        }
        check_bias(&weight, bias.as_ref())?;
        Ok(Self {
            weight,
            bias,
            config,
        })
    }

    /// The weight, `(C_out, C_in, kh, kw)`.
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

impl Module for Conv2d {
    fn forward(&self, xs: &Tensor) -> candle_core::Result<Tensor> {
        let ys = op::conv2d(xs, &self.weight, self.config)?;
        match &self.bias {
            None => Ok(ys),
            Some(b) => crate::fused::bias_add(&ys, b),
        }
    }
}

/// A [`Conv2d`] with bias and a square kernel whose tensors are `weight` and `bias` under `vb`
/// (PyTorch's `nn.Conv2d` names); new variables start from PyTorch's default init (uniform in
/// `±1/sqrt(C_in k^2)` for both; candle-nn's own `conv2d` draws Kaiming-normal weights, which
/// would change the networks' start relative to the paper's PyTorch code).
pub fn conv2d(
    in_channels: usize,
    out_channels: usize,
    kernel: usize,
    config: ConvConfig,
    vb: VarBuilder,
) -> Result<Conv2d> {
    let (weight, bias) = layer_tensors(in_channels, out_channels, kernel, 2, true, vb)?;
    Conv2d::new(weight, bias, config)
}

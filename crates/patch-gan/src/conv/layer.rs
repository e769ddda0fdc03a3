//! `Conv<AXES>`: the convolution layer over 2 or 3 spatial axes ([`Conv2d`], [`Conv3d`]).

use candle_core::{Module, Tensor};
use candle_nn::VarBuilder;

use super::{check_bias, layer_tensors, op, ConvConfig};
use crate::error::{invalid, Result};

/// A convolution over `AXES` spatial axes (2 or 3) with PyTorch's layout: weight `(C_out, C_in,
/// k, ..)` with `AXES` kernel axes, optional bias `(C_out,)`, input `(N, C_in, ..)` to output
/// `(N, C_out, ..)`. Use it as [`Conv2d`] (images, on [`functional::conv2d`](crate::functional::conv2d))
/// or [`Conv3d`] (volumes, on [`functional::conv3d`](crate::functional::conv3d)); both run the
/// same CPU kernels and are differentiable to any order.
///
/// ```
/// use candle_core::{DType, Device, Module, Tensor};
/// use candle_nn::{VarBuilder, VarMap};
/// use patch_gan::{conv2d, conv3d, ConvConfig};
/// let varmap = VarMap::new();
/// let vb = VarBuilder::from_varmap(&varmap, DType::F32, &Device::Cpu);
/// let conv = conv3d(4, 8, 3, ConvConfig::default().with_padding(1), vb.pp("conv3"))?;
/// let y = conv.forward(&Tensor::zeros((1, 4, 5, 6, 7), DType::F32, &Device::Cpu)?)?;
/// assert_eq!(y.dims(), &[1, 8, 5, 6, 7]);
/// let conv = conv2d(4, 8, 3, ConvConfig::default(), vb.pp("conv2"))?;
/// let y = conv.forward(&Tensor::zeros((2, 4, 10, 12), DType::F32, &Device::Cpu)?)?;
/// assert_eq!(y.dims(), &[2, 8, 8, 10]);
/// # Ok::<(), patch_gan::Error>(())
/// ```
#[derive(Debug, Clone)]
pub struct Conv<const AXES: usize> {
    weight: Tensor,
    bias: Option<Tensor>,
    config: ConvConfig,
}

/// The 2D convolution of the critics and the upsampler: weight `(C_out, C_in, kh, kw)`, input
/// `(N, C_in, H, W)`. Unlike `candle_nn::Conv2d`, its CPU backward pass is itself
/// differentiable through our kernels, which is what the gradient penalty's second-order
/// gradients run on.
pub type Conv2d = Conv<2>;

/// The 3D convolution (candle has none): weight `(C_out, C_in, kd, kh, kw)`, input `(N, C_in,
/// D, H, W)`.
pub type Conv3d = Conv<3>;

impl<const AXES: usize> Conv<AXES> {
    /// A layer from ready tensors: `weight` `(C_out, C_in, k, ..)` with `AXES` kernel axes and
    /// `bias` `(C_out,)`. Errors on other shapes, or `AXES` other than 2 and 3.
    pub fn new(weight: Tensor, bias: Option<Tensor>, config: ConvConfig) -> Result<Self> {
        if !(2..=3).contains(&AXES) || weight.rank() != AXES + 2 {
            let axes = ["kh, kw", "kd, kh, kw"][AXES.clamp(2, 3) - 2];
            return Err(invalid(
                "weight",
                format!("expected (C_out, C_in, {axes}), got {:?}", weight.shape()),
            ));
        }
        check_bias(&weight, bias.as_ref())?;
        Ok(Self {
            weight,
            bias,
            config,
        })
    }

    /// The weight, `(C_out, C_in, k, ..)`.
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

impl<const AXES: usize> Module for Conv<AXES> {
    fn forward(&self, xs: &Tensor) -> candle_core::Result<Tensor> {
        let ys = if AXES == 2 {
            op::conv2d(xs, &self.weight, self.config)?
        } else {
            op::conv3d(xs, &self.weight, self.config)?
        };
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

//! `Conv3d`: a 3D convolution layer for candle, with PyTorch's weight layout, names and init.

mod cpu;
pub(crate) mod op;
mod slices;

use candle_core::{Module, Tensor};
use candle_nn::VarBuilder;

use crate::error::{invalid, Result};
use crate::init::torch_conv_init;

/// Padding (zeros, on every side of every spatial axis) and stride of a [`Conv3d`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Conv3dConfig {
    /// Zeros added before and after each of D, H, W.
    pub padding: usize,
    /// Step between output voxels, at least 1.
    pub stride: usize,
}

impl Default for Conv3dConfig {
    fn default() -> Self {
        Self {
            padding: 0,
            stride: 1,
        }
    }
}

impl Conv3dConfig {
    /// The same config with `padding` zeros on every side.
    pub fn with_padding(self, padding: usize) -> Self {
        Self { padding, ..self }
    }

    /// The same config with step `stride`.
    pub fn with_stride(self, stride: usize) -> Self {
        Self { stride, ..self }
    }
}

/// A 3D convolution: weight `(C_out, C_in, k, k, k)`, optional bias `(C_out,)`, input
/// `(N, C_in, D, H, W)`, output `(N, C_out, D_out, H_out, W_out)`.
///
/// ```
/// use candle_core::{DType, Device, Module, Tensor};
/// use candle_nn::{VarBuilder, VarMap};
/// use patch_gan::{conv3d, Conv3dConfig};
/// let varmap = VarMap::new();
/// let vb = VarBuilder::from_varmap(&varmap, DType::F32, &Device::Cpu);
/// let conv = conv3d(4, 8, 3, Conv3dConfig::default().with_padding(1), vb.pp("conv"))?;
/// let y = conv.forward(&Tensor::zeros((1, 4, 5, 6, 7), DType::F32, &Device::Cpu)?)?;
/// assert_eq!(y.dims(), &[1, 8, 5, 6, 7]);
/// # Ok::<(), patch_gan::Error>(())
/// ```
#[derive(Debug, Clone)]
pub struct Conv3d {
    weight: Tensor,
    bias: Option<Tensor>,
    config: Conv3dConfig,
}

impl Conv3d {
    /// A layer from ready tensors: `weight` `(C_out, C_in, k, k, k)` and `bias` `(C_out,)`.
    pub fn new(weight: Tensor, bias: Option<Tensor>, config: Conv3dConfig) -> Result<Self> {
        let &[c_out, _, kd, kh, kw] = weight.dims() else {
            return Err(invalid(
                "weight",
                format!("expected (C_out, C_in, k, k, k), got {:?}", weight.shape()),
            ));
        };
        if kd != kh || kd != kw {
            return Err(invalid(
                "weight",
                format!("only cubic kernels are supported, got {:?}", weight.shape()),
            ));
        }
        if let Some(b) = &bias {
            if b.dims() != [c_out] {
                return Err(invalid(
                    "bias",
                    format!("expected ({c_out},), got {:?}", b.shape()),
                ));
            }
        }
        Ok(Self {
            weight,
            bias,
            config,
        })
    }

    /// The weight, `(C_out, C_in, k, k, k)`.
    pub fn weight(&self) -> &Tensor {
        &self.weight
    }

    /// The bias, `(C_out,)`, if any.
    pub fn bias(&self) -> Option<&Tensor> {
        self.bias.as_ref()
    }

    /// Padding and stride.
    pub fn config(&self) -> Conv3dConfig {
        self.config
    }
}

impl Module for Conv3d {
    fn forward(&self, xs: &Tensor) -> candle_core::Result<Tensor> {
        let ys = op::conv3d(xs, &self.weight, self.config)?;
        match &self.bias {
            None => Ok(ys),
            Some(b) => ys.broadcast_add(&b.reshape((1, (), 1, 1, 1))?),
        }
    }
}

/// A [`Conv3d`] with bias whose tensors are `weight` and `bias` under `vb`, as in a PyTorch
/// `nn.Conv3d` state dict; new variables start from PyTorch's default init (uniform in
/// `±1/sqrt(C_in k^3)` for both).
pub fn conv3d(
    in_channels: usize,
    out_channels: usize,
    kernel: usize,
    config: Conv3dConfig,
    vb: VarBuilder,
) -> Result<Conv3d> {
    build(in_channels, out_channels, kernel, config, true, vb)
}

/// Like [`conv3d`] without a bias (only `weight` is read).
pub fn conv3d_no_bias(
    in_channels: usize,
    out_channels: usize,
    kernel: usize,
    config: Conv3dConfig,
    vb: VarBuilder,
) -> Result<Conv3d> {
    build(in_channels, out_channels, kernel, config, false, vb)
}

fn build(
    in_channels: usize,
    out_channels: usize,
    kernel: usize,
    config: Conv3dConfig,
    with_bias: bool,
    vb: VarBuilder,
) -> Result<Conv3d> {
    if in_channels == 0 || out_channels == 0 || kernel == 0 {
        return Err(invalid(
            "conv3d",
            format!("channels and kernel must be positive, got {in_channels} -> {out_channels}, k = {kernel}"),
        ));
    }
    let (w_init, b_init) = torch_conv_init(in_channels * kernel.pow(3));
    let weight = vb.get_with_hints(
        (out_channels, in_channels, kernel, kernel, kernel),
        "weight",
        w_init,
    )?;
    let bias = if with_bias {
        Some(vb.get_with_hints(out_channels, "bias", b_init)?)
    } else {
        None
    };
    Conv3d::new(weight, bias, config)
}

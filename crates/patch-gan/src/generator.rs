//! `Generator3d`: the paper's L-layer 3D convolutional generator G_n (n < N).

use candle_core::{ModuleT, Tensor};
use candle_nn::{Module, VarBuilder};

use crate::conv::{conv3d, op, Conv3d, ConvConfig};
use crate::error::{invalid, Result};
use crate::norm::{batch_norm3d, BatchNorm3d, LEAKY_SLOPE};

/// Shape of a [`Generator3d`]. The default is the paper's G_1 with L = 5 (table "generators"):
/// 3 input channels (noise plus the CSG grid), 32 hidden channels, 4 output channels
/// (raw density and RGB), 3^3 kernels with padding 1.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Generator3dConfig {
    /// Number of Conv3d layers L, at least 2 (the paper uses 5 or 7).
    pub layers: usize,
    /// Hidden channels (32).
    pub channels: usize,
    /// Input channels: 3 at the coarsest scale, 4 above.
    pub in_channels: usize,
    /// Output channels (4: sigma and RGB, raw).
    pub out_channels: usize,
    /// Odd kernel size (3); padding is `kernel / 2`, so every layer keeps the volume's size.
    pub kernel: usize,
}

impl Default for Generator3dConfig {
    fn default() -> Self {
        Self {
            layers: 5,
            channels: 32,
            in_channels: 3,
            out_channels: 4,
            kernel: 3,
        }
    }
}

impl Generator3dConfig {
    /// The paper's generator for scale `n` (1-based): 3 input channels at n = 1, 4 above.
    pub fn for_scale(n: usize, layers: usize) -> Self {
        let in_channels = if n <= 1 { 3 } else { 4 };
        Self {
            layers,
            in_channels,
            ..Self::default()
        }
    }

    /// The same config with `layers` Conv3d layers.
    pub fn with_layers(self, layers: usize) -> Self {
        Self { layers, ..self }
    }

    /// The same config with `in_channels` input channels.
    pub fn with_in_channels(self, in_channels: usize) -> Self {
        Self {
            in_channels,
            ..self
        }
    }

    /// Voxels along each axis that one output voxel depends on: `1 + L (kernel - 1)`, i.e.
    /// `2L + 1` for 3^3 kernels (11 for L = 5, 15 for L = 7).
    pub fn receptive_field(&self) -> usize {
        1 + self.layers * (self.kernel - 1)
    }

    fn validate(&self) -> Result<()> {
        if self.layers < 2 {
            return Err(invalid(
                "Generator3d layers",
                format!("need at least 2, got {}", self.layers),
            ));
        }
        if self.kernel % 2 == 0 {
            return Err(invalid(
                "Generator3d kernel",
                format!("must be odd, got {}", self.kernel),
            ));
        }
        if self.channels == 0 || self.in_channels == 0 || self.out_channels == 0 {
            return Err(invalid("Generator3d channels", "must be positive"));
        }
        Ok(())
    }
}

/// The 3D generator: `L - 1` blocks of Conv3d + BatchNorm3d + LeakyReLU(0.2), then a Conv3d to
/// `out_channels`. Every layer keeps the spatial size, so `(N, C_in, D, H, W)` maps to
/// `(N, C_out, D, H, W)`.
///
/// Checkpoint names under the given `VarBuilder`: `blocks.{i}.conv.{weight,bias}`,
/// `blocks.{i}.bn.{weight,bias,running_mean,running_var}` for `i < L - 1`, and
/// `tail.{weight,bias}`.
///
/// ```
/// use candle_core::{DType, Device, ModuleT, Tensor};
/// use candle_nn::{VarBuilder, VarMap};
/// use patch_gan::{Generator3d, Generator3dConfig};
/// let varmap = VarMap::new();
/// let vb = VarBuilder::from_varmap(&varmap, DType::F32, &Device::Cpu);
/// let g2 = Generator3d::new(&Generator3dConfig::for_scale(2, 5), vb.pp("g2"))?;
/// let z = Tensor::zeros((1, 4, 6, 6, 6), DType::F32, &Device::Cpu)?;
/// let prev_up = Tensor::ones((1, 4, 6, 6, 6), DType::F32, &Device::Cpu)?;
/// let v = g2.forward_residual(&z, &prev_up, true)?;
/// assert_eq!(v.dims(), &[1, 4, 6, 6, 6]);
/// # Ok::<(), patch_gan::Error>(())
/// ```
#[derive(Debug, Clone)]
pub struct Generator3d {
    blocks: Vec<(Conv3d, BatchNorm3d)>,
    tail: Conv3d,
    config: Generator3dConfig,
}

impl Generator3d {
    /// Builds (or loads) the generator's tensors under `vb`.
    pub fn new(config: &Generator3dConfig, vb: VarBuilder) -> Result<Self> {
        config.validate()?;
        let conv_cfg = ConvConfig::default().with_padding(config.kernel / 2);
        let blocks = (0..config.layers - 1)
            .map(|i| {
                let vb = vb.pp("blocks").pp(i);
                let c_in = if i == 0 {
                    config.in_channels
                } else {
                    config.channels
                };
                let conv = conv3d(
                    c_in,
                    config.channels,
                    config.kernel,
                    conv_cfg,
                    vb.pp("conv"),
                )?;
                Ok((conv, batch_norm3d(config.channels, vb.pp("bn"))?))
            })
            .collect::<Result<Vec<_>>>()?;
        let tail = conv3d(
            config.channels,
            config.out_channels,
            config.kernel,
            conv_cfg,
            vb.pp("tail"),
        )?;
        Ok(Self {
            blocks,
            tail,
            config: *config,
        })
    }

    /// The configuration it was built with.
    pub fn config(&self) -> &Generator3dConfig {
        &self.config
    }

    /// The residual form of the finer scales: `prev_up + G(z + prev_up)`, i.e.
    /// `V_n = up(V_{n-1}) + G_n(z_n + up(V_{n-1}))`. Needs `in_channels == out_channels` and `z`,
    /// `prev_up` of the same shape.
    pub fn forward_residual(&self, z: &Tensor, prev_up: &Tensor, train: bool) -> Result<Tensor> {
        self.forward_residual_masked(z, prev_up, None, train)
    }

    /// [`Generator3d::forward_residual`] with the residual applied only where `mask` is 1:
    /// `prev_up + mask * G(z + prev_up)`, `mask` of shape `(B, 1, D, H, W)` (broadcast over the
    /// channels; 0 and 1, or any weights). The generator still convolves every voxel: this is
    /// the active-set model's math, computed densely; where the mask is 0 the volume stays
    /// `prev_up` and no gradient reaches the generator from there.
    ///
    /// ```
    /// use candle_core::{DType, Device, Tensor};
    /// use candle_nn::{VarBuilder, VarMap};
    /// use patch_gan::{Generator3d, Generator3dConfig};
    /// let varmap = VarMap::new();
    /// let vb = VarBuilder::from_varmap(&varmap, DType::F32, &Device::Cpu);
    /// let g2 = Generator3d::new(&Generator3dConfig::for_scale(2, 5), vb.pp("g2"))?;
    /// let z = Tensor::ones((1, 4, 6, 6, 6), DType::F32, &Device::Cpu)?;
    /// let prev_up = Tensor::zeros((1, 4, 6, 6, 6), DType::F32, &Device::Cpu)?;
    /// let nothing_active = Tensor::zeros((1, 1, 6, 6, 6), DType::F32, &Device::Cpu)?;
    /// let v = g2.forward_residual_masked(&z, &prev_up, Some(&nothing_active), true)?;
    /// assert_eq!(v.abs()?.sum_all()?.to_scalar::<f32>()?, 0.0);
    /// # Ok::<(), patch_gan::Error>(())
    /// ```
    pub fn forward_residual_masked(
        &self,
        z: &Tensor,
        prev_up: &Tensor,
        mask: Option<&Tensor>,
        train: bool,
    ) -> Result<Tensor> {
        if self.config.in_channels != self.config.out_channels {
            return Err(invalid(
                "Generator3d residual",
                format!(
                    "needs in_channels == out_channels, have {} and {}",
                    self.config.in_channels, self.config.out_channels
                ),
            ));
        }
        if z.shape() != prev_up.shape() {
            return Err(invalid(
                "Generator3d residual",
                format!(
                    "noise {:?} and volume {:?} differ in shape",
                    z.shape(),
                    prev_up.shape()
                ),
            ));
        }
        if let Some(mask) = mask {
            let (batch, _, d, h, w) = prev_up.dims5()?;
            if mask.dims() != [batch, 1, d, h, w] {
                return Err(invalid(
                    "Generator3d residual",
                    format!(
                        "mask {:?} is not one channel of the volume {:?}",
                        mask.shape(),
                        prev_up.shape()
                    ),
                ));
            }
        }
        let residual = self.forward_t(&(z + prev_up)?, train)?;
        let residual = match mask {
            None => residual,
            Some(mask) => residual.broadcast_mul(mask)?,
        };
        Ok((prev_up + residual)?)
    }
}

impl ModuleT for Generator3d {
    fn forward_t(&self, xs: &Tensor, train: bool) -> candle_core::Result<Tensor> {
        let mut h = xs.clone();
        for (conv, bn) in &self.blocks {
            // The convolution's bias goes to the fused BatchNorm + LeakyReLU, which needs it in
            // eval mode only (batch statistics cancel it).
            let convolved = op::conv3d(&h, conv.weight(), conv.config())?;
            h = bn.forward_activated(&convolved, conv.bias(), LEAKY_SLOPE, train)?;
        }
        self.tail.forward(&h)
    }
}

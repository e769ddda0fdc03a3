//! `PatchDiscriminator2d`: the paper's 2D patch critic D_n.

use candle_core::{Module, Tensor};
use candle_nn::VarBuilder;

use crate::conv::{conv2d, op, Conv2d, ConvConfig};
use crate::error::{invalid, Result};
use crate::fused::bias_leaky_relu;
use crate::norm::{leaky_relu, LEAKY_SLOPE};

/// Kernel size of every discriminator layer.
const KERNEL: usize = 3;

/// Receptive field, in pixels along each axis, of `layers` unpadded 3x3 stride-1 convolutions:
/// each layer widens it by 2, so it is `2 L + 1` (11 for L = 5, 15 for L = 7). One patch-map
/// value depends on exactly this square of input pixels, and the patch map is `2 L` pixels
/// smaller than the input along each axis.
///
/// ```
/// assert_eq!(patch_gan::receptive_field(5), 11);
/// assert_eq!(patch_gan::receptive_field(7), 15);
/// ```
pub fn receptive_field(layers: usize) -> usize {
    2 * layers + 1
}

/// Shape of a [`PatchDiscriminator2d`]. The default is the paper's D_n for n < N with L = 5:
/// 4 input channels (RGB + depth), 32 hidden channels.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PatchDiscriminator2dConfig {
    /// Number of Conv2d layers L, at least 2 (the paper uses 5 or 7).
    pub layers: usize,
    /// Hidden channels (32).
    pub channels: usize,
    /// Input channels: 4 (RGB + depth) for n < N, 6 (joint [G_N output, naive upsample]) at N.
    pub in_channels: usize,
}

impl Default for PatchDiscriminator2dConfig {
    fn default() -> Self {
        Self {
            layers: 5,
            channels: 32,
            in_channels: 4,
        }
    }
}

impl PatchDiscriminator2dConfig {
    /// The same config with `layers` layers.
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

    /// [`receptive_field`] of this many layers.
    pub fn receptive_field(&self) -> usize {
        receptive_field(self.layers)
    }
}

/// The patch critic: `L - 1` unpadded 3x3 Conv2d + LeakyReLU(0.2) layers, then an unpadded 3x3
/// Conv2d to one channel. `(N, C, H, W)` maps to the patch map `(N, 1, H - 2L, W - 2L)`; its mean
/// is the critic's score ([`PatchDiscriminator2d::score`]).
///
/// Checkpoint names: `blocks.{i}.conv.{weight,bias}` for `i < L - 1`, and `tail.{weight,bias}`.
///
/// ```
/// use candle_core::{DType, Device, Module, Tensor};
/// use candle_nn::{VarBuilder, VarMap};
/// use patch_gan::{PatchDiscriminator2d, PatchDiscriminator2dConfig};
/// let varmap = VarMap::new();
/// let vb = VarBuilder::from_varmap(&varmap, DType::F32, &Device::Cpu);
/// let d = PatchDiscriminator2d::new(&PatchDiscriminator2dConfig::default(), vb.pp("d1"))?;
/// let map = d.forward(&Tensor::zeros((2, 4, 32, 32), DType::F32, &Device::Cpu)?)?;
/// assert_eq!(map.dims(), &[2, 1, 22, 22]);
/// # Ok::<(), patch_gan::Error>(())
/// ```
#[derive(Debug, Clone)]
pub struct PatchDiscriminator2d {
    blocks: Vec<Conv2d>,
    tail: Conv2d,
    config: PatchDiscriminator2dConfig,
}

impl PatchDiscriminator2d {
    /// Builds (or loads) the discriminator's tensors under `vb`.
    pub fn new(config: &PatchDiscriminator2dConfig, vb: VarBuilder) -> Result<Self> {
        if config.layers < 2 {
            return Err(invalid(
                "PatchDiscriminator2d layers",
                format!("need at least 2, got {}", config.layers),
            ));
        }
        if config.channels == 0 || config.in_channels == 0 {
            return Err(invalid("PatchDiscriminator2d channels", "must be positive"));
        }
        let blocks = (0..config.layers - 1)
            .map(|i| {
                let c_in = if i == 0 {
                    config.in_channels
                } else {
                    config.channels
                };
                conv2d(
                    c_in,
                    config.channels,
                    KERNEL,
                    ConvConfig::default(),
                    vb.pp("blocks").pp(i).pp("conv"),
                )
            })
            .collect::<Result<Vec<_>>>()?;
        let tail = conv2d(
            config.channels,
            1,
            KERNEL,
            ConvConfig::default(),
            vb.pp("tail"),
        )?;
        Ok(Self {
            blocks,
            tail,
            config: *config,
        })
    }

    /// The configuration it was built with.
    pub fn config(&self) -> &PatchDiscriminator2dConfig {
        &self.config
    }

    /// One score per image: the mean of the patch map, shape `(N,)`.
    pub fn score(&self, xs: &Tensor) -> Result<Tensor> {
        Ok(self.forward(xs)?.flatten_from(1)?.mean(1)?)
    }
}

impl Module for PatchDiscriminator2d {
    fn forward(&self, xs: &Tensor) -> candle_core::Result<Tensor> {
        let (_, _, h, w) = xs.dims4()?;
        let field = self.config.receptive_field();
        if h < field || w < field {
            return Err(invalid(
                "PatchDiscriminator2d input",
                format!("{h}x{w} is smaller than the receptive field {field}"),
            )
            .into());
        }
        let mut x = xs.clone();
        for conv in &self.blocks {
            let convolved = op::conv2d(&x, conv.weight(), conv.config())?;
            x = match conv.bias() {
                Some(bias) => bias_leaky_relu(&convolved, bias, LEAKY_SLOPE)?,
                None => leaky_relu(&convolved, LEAKY_SLOPE)?,
            };
        }
        self.tail.forward(&x)
    }
}

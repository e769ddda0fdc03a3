//! VGG-19 features (torchvision's `vgg19().features`), loaded from a safetensors file.

use std::fmt;
use std::path::Path;

use candle_core::{DType, Device, Module, Tensor};
use candle_nn::{Conv2d, Conv2dConfig, VarBuilder};

use super::{FeatureExtractor, FeatureMap};
use crate::error::{invalid, Error, Result};

/// Per block: number of 3x3 convolutions and their output channels (VGG-19, configuration E).
const BLOCKS: [(usize, usize); 5] = [(2, 64), (2, 128), (4, 256), (4, 512), (4, 512)];

/// torchvision's ImageNet statistics, for inputs in [0, 1].
const IMAGENET_MEAN: [f32; 3] = [0.485, 0.456, 0.406];
const IMAGENET_STD: [f32; 3] = [0.229, 0.224, 0.225];

/// A VGG-19 activation after a ReLU, named `relu{block}_{conv}` (e.g. `relu3_1`), blocks 1..=5.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct VggLayer {
    block: usize,
    conv: usize,
}

impl VggLayer {
    /// Names `relu{block}_{conv}`; errors if VGG-19 has no such layer (blocks 1 and 2 have two
    /// convolutions, blocks 3 to 5 four).
    ///
    /// ```
    /// let l = swd_loss::VggLayer::relu(3, 1)?;
    /// assert_eq!(l.to_string(), "relu3_1");
    /// assert!(swd_loss::VggLayer::relu(1, 3).is_err());
    /// # Ok::<(), swd_loss::Error>(())
    /// ```
    pub fn relu(block: usize, conv: usize) -> Result<Self> {
        match BLOCKS.get(block.wrapping_sub(1)) {
            Some(&(convs, _)) if (1..=convs).contains(&conv) => Ok(Self { block, conv }),
            _ => Err(invalid(
                "VGG layer",
                format!("VGG-19 has no layer relu{block}_{conv}"),
            )),
        }
    }

    /// Returns the block (1..=5).
    #[must_use]
    pub fn block(self) -> usize {
        self.block
    }

    /// Returns the convolution within the block (from 1).
    #[must_use]
    pub fn conv(self) -> usize {
        self.conv
    }

    /// Returns the layer's channel count.
    #[must_use]
    pub fn channels(self) -> usize {
        BLOCKS[self.block - 1].1
    }

    /// Returns the index of the layer's convolution among all 16 (0-based, in forward order).
    fn ordinal(self) -> usize {
        BLOCKS[..self.block - 1].iter().map(|b| b.0).sum::<usize>() + self.conv - 1
    }
}

impl fmt::Display for VggLayer {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "relu{}_{}", self.block, self.conv)
    }
}

/// The 2x2 downsampling between blocks.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Pooling {
    /// Max pooling, as the network was trained (torchvision).
    #[default]
    Max,
    /// Average pooling, which Heitz et al. use for smoother gradients.
    Average,
}

/// How each 3x3 convolution pads its input by one pixel.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Padding {
    /// Zeros, as the network was trained (torchvision).
    #[default]
    Zeros,
    /// Mirror without repeating the edge (Heitz et al.), avoiding dark-border artefacts; a side
    /// of one pixel is repeated instead.
    Reflect,
}

/// Settings of a [`Vgg19`] extractor.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Vgg19Config {
    /// The activations to return (any order; returned in forward order, without repeats).
    pub layers: Vec<VggLayer>,
    /// Downsampling between blocks.
    pub pooling: Pooling,
    /// Convolution padding.
    pub padding: Padding,
    /// Whether inputs are RGB in [0, 1] to be normalised with ImageNet's mean
    /// (0.485, 0.456, 0.406) and std (0.229, 0.224, 0.225), as torchvision's weights expect;
    /// `false` feeds images unchanged.
    pub imagenet_normalize: bool,
}

impl Default for Vgg19Config {
    /// `relu1_1`, `relu2_1`, `relu3_1`, `relu4_1`, `relu5_1` with torchvision's max pooling, zero
    /// padding and ImageNet normalisation.
    fn default() -> Self {
        Self {
            layers: (1..=5).map(|b| VggLayer { block: b, conv: 1 }).collect(),
            pooling: Pooling::Max,
            padding: Padding::Zeros,
            imagenet_normalize: true,
        }
    }
}

impl Vgg19Config {
    /// The setting of Heitz et al.'s PyTorch code: the 12 layers `relu1_1` to `relu4_4`,
    /// average pooling and reflect padding.
    #[must_use]
    pub fn heitz() -> Self {
        let layers = BLOCKS[..4]
            .iter()
            .enumerate()
            .flat_map(|(b, &(convs, _))| {
                (1..=convs).map(move |c| VggLayer {
                    block: b + 1,
                    conv: c,
                })
            })
            .collect();
        Self {
            layers,
            pooling: Pooling::Average,
            padding: Padding::Reflect,
            imagenet_normalize: true,
        }
    }
}

/// VGG-19's convolutional part, run up to the deepest requested layer.
///
/// Weights use torchvision's names, `features.{i}.weight` `(out, in, 3, 3)` and
/// `features.{i}.bias`, where i is the module index in `vgg19().features` (convolutions at 0,
/// 2, 5, 7, 10, 12, 14, 16, 19, ...); only the convolutions up to the deepest requested layer are
/// read. Inputs are `(B, 3, H, W)` RGB; both sides must be at least `2^(deepest block - 1)`.
///
/// ```
/// use candle_core::{DType, Device, Tensor};
/// use candle_nn::VarBuilder;
/// use swd_loss::{FeatureExtractor, Vgg19, Vgg19Config, VggLayer};
///
/// // Zero weights stand in for a real checkpoint (see `Vgg19::from_safetensors`).
/// let config = Vgg19Config { layers: vec![VggLayer::relu(2, 1)?], ..Vgg19Config::default() };
/// let vgg = Vgg19::new(config, VarBuilder::zeros(DType::F32, &Device::Cpu))?;
/// let maps = vgg.extract(&Tensor::zeros((1, 3, 8, 8), DType::F32, &Device::Cpu)?)?;
/// assert_eq!(maps[0].values.dims(), &[1, 128, 4, 4]);
/// # Ok::<(), swd_loss::Error>(())
/// ```
#[derive(Debug, Clone)]
pub struct Vgg19 {
    convs: Vec<Conv2d>,
    /// Per convolution in `convs`: whether its activation is returned.
    taps: Vec<bool>,
    layers: Vec<VggLayer>,
    config: Vgg19Config,
}

impl Vgg19 {
    /// Builds the network from a [`VarBuilder`] rooted at the checkpoint's top level (tensors
    /// `features.*`). Errors on an empty layer list or missing or misshapen weights.
    pub fn new(config: Vgg19Config, vb: VarBuilder) -> Result<Self> {
        let mut layers = config.layers.clone();
        layers.sort();
        layers.dedup();
        let deepest = *layers
            .last()
            .ok_or_else(|| invalid("layers", "at least one VGG layer is needed"))?;
        let conv_cfg = Conv2dConfig {
            padding: match config.padding {
                Padding::Zeros => 1,
                Padding::Reflect => 0,
            },
            ..Conv2dConfig::default()
        };
        let features = vb.pp("features");
        let mut convs = Vec::with_capacity(deepest.ordinal() + 1);
        let mut taps = Vec::with_capacity(deepest.ordinal() + 1);
        let (mut index, mut in_channels) = (0, 3);
        'blocks: for (b, &(n_convs, channels)) in BLOCKS.iter().enumerate() {
            for c in 0..n_convs {
                let layer = VggLayer {
                    block: b + 1,
                    conv: c + 1,
                };
                convs.push(candle_nn::conv2d(
                    in_channels,
                    channels,
                    3,
                    conv_cfg,
                    features.pp(index.to_string()),
                )?);
                taps.push(layers.binary_search(&layer).is_ok());
                (index, in_channels) = (index + 2, channels);
                if layer == deepest {
                    break 'blocks;
                }
            }
            index += 1; // the pooling module
        }
        Ok(Self {
            convs,
            taps,
            layers,
            config,
        })
    }

    /// Loads the weights from a safetensors file with torchvision's names (see
    /// `docs/swd-loss.md` for converting torchvision's checkpoint), as `f32` on `device`.
    pub fn from_safetensors(
        path: impl AsRef<Path>,
        config: Vgg19Config,
        device: &Device,
    ) -> Result<Self> {
        let path = path.as_ref();
        let bytes = std::fs::read(path).map_err(|source| Error::Io {
            path: path.to_path_buf(),
            source,
        })?;
        let vb = VarBuilder::from_buffered_safetensors(bytes, DType::F32, device)?;
        Self::new(config, vb)
    }

    /// Returns the returned layers, in forward order.
    #[must_use]
    pub fn layers(&self) -> &[VggLayer] {
        &self.layers
    }

    /// Returns the settings.
    #[must_use]
    pub fn config(&self) -> &Vgg19Config {
        &self.config
    }

    /// Pads by one pixel for [`Padding::Reflect`] (zero padding is inside the convolution).
    fn pad(&self, x: &Tensor) -> Result<Tensor> {
        if self.config.padding == Padding::Zeros {
            return Ok(x.clone());
        }
        let mut x = x.clone();
        for dim in [2, 3] {
            let n = x.dim(dim)?;
            let inner = usize::from(n > 1);
            let first = x.narrow(dim, inner, 1)?;
            let last = x.narrow(dim, n - 1 - inner, 1)?;
            x = Tensor::cat(&[&first, &x, &last], dim)?;
        }
        Ok(x)
    }

    /// Downsamples 2x2 (an odd last row or column is dropped, as in torchvision).
    ///
    /// Written as reductions over a `(.., h/2, 2, w/2, 2)` view rather than candle's pooling
    /// ops, whose backward in candle 0.11 scales max-pool gradients by 1/4 and maps gradients
    /// back through a nearest upsampling that is wrong for odd sides.
    fn pool(&self, x: &Tensor) -> Result<Tensor> {
        let (b, c, h, w) = x.dims4()?;
        let (oh, ow) = (h / 2, w / 2);
        let blocks = x
            .narrow(2, 0, 2 * oh)?
            .narrow(3, 0, 2 * ow)?
            .reshape((b, c, oh, 2, ow, 2))?;
        Ok(match self.config.pooling {
            Pooling::Max => blocks.max(5)?.max(3)?,
            Pooling::Average => blocks.mean(5)?.mean(3)?,
        })
    }

    fn normalize(&self, images: &Tensor) -> Result<Tensor> {
        if !self.config.imagenet_normalize {
            return Ok(images.clone());
        }
        let dev = images.device();
        let mean = Tensor::new(&IMAGENET_MEAN, dev)?
            .to_dtype(images.dtype())?
            .reshape((1, 3, 1, 1))?;
        let std = Tensor::new(&IMAGENET_STD, dev)?
            .to_dtype(images.dtype())?
            .reshape((1, 3, 1, 1))?;
        Ok(images.broadcast_sub(&mean)?.broadcast_div(&std)?)
    }
}

impl FeatureExtractor for Vgg19 {
    fn layer_count(&self) -> usize {
        self.layers.len()
    }

    fn extract(&self, images: &Tensor) -> Result<Vec<FeatureMap>> {
        let (_, c, h, w) = images.dims4().map_err(|_| {
            invalid(
                "images",
                format!("expected (B, 3, H, W), got shape {:?}", images.dims()),
            )
        })?;
        let deepest_block = self.layers.last().map_or(1, |l| l.block);
        let min_side = 1 << (deepest_block - 1);
        if c != 3 || h < min_side || w < min_side {
            return Err(invalid(
                "images",
                format!("VGG-19 up to block {deepest_block} needs (B, 3, H, W) with H, W >= {min_side}, got {:?}", images.dims()),
            ));
        }
        let dtype = self.convs[0].weight().dtype();
        let mut x = self.normalize(&images.to_dtype(dtype)?)?;
        let mut maps = Vec::with_capacity(self.layers.len());
        let mut convs = self.convs.iter().zip(&self.taps);
        for &(n_convs, _) in &BLOCKS {
            for _ in 0..n_convs {
                let Some((conv, &tap)) = convs.next() else {
                    return Ok(maps);
                };
                x = conv.forward(&self.pad(&x)?)?.relu()?;
                if tap {
                    maps.push(FeatureMap {
                        values: x.clone(),
                        patch: 1,
                    });
                }
            }
            if convs.len() == 0 {
                break;
            }
            x = self.pool(&x)?;
        }
        Ok(maps)
    }
}

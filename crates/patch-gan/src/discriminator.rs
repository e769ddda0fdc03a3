//! `PatchDiscriminator2d`: the paper's 2D patch critic D_n.

use candle_core::{Module, Tensor};
use candle_nn::VarBuilder;
use rand::Rng;

use crate::conv::{conv2d, op, Conv2d, ConvConfig};
use crate::error::{invalid, Result};
use crate::fused::{bias_leaky_relu, leaky_grad};
use crate::norm::{leaky_relu, LEAKY_SLOPE};
use crate::wgan::{mixed_images, penalty_of_gradient, GradientPenalty};

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

impl PatchDiscriminator2d {
    /// The critic's WGAN loss [`critic_loss`](crate::critic_loss)`(D(real), D(fake))`, i.e.
    /// `mean(D(fake)) - mean(D(real))` over all patches, with both batches through one forward
    /// pass (half the convolution calls, each on twice the images). `real` and `fake` may hold
    /// different numbers of images of the same channels and size.
    ///
    /// ```
    /// use candle_core::{DType, Device, Module, Tensor};
    /// use candle_nn::{VarBuilder, VarMap};
    /// use patch_gan::{critic_loss, PatchDiscriminator2d, PatchDiscriminator2dConfig};
    /// let varmap = VarMap::new();
    /// let vb = VarBuilder::from_varmap(&varmap, DType::F64, &Device::Cpu);
    /// let d = PatchDiscriminator2d::new(&PatchDiscriminator2dConfig::default().with_layers(3), vb)?;
    /// let real = Tensor::rand(0f64, 1., (2, 4, 12, 12), &Device::Cpu)?;
    /// let fake = Tensor::rand(0f64, 1., (3, 4, 12, 12), &Device::Cpu)?;
    /// let joint = d.critic_loss(&real, &fake)?.to_scalar::<f64>()?;
    /// let apart = critic_loss(&d.forward(&real)?, &d.forward(&fake)?)?.to_scalar::<f64>()?;
    /// assert!((joint - apart).abs() < 1e-12);
    /// # Ok::<(), patch_gan::Error>(())
    /// ```
    pub fn critic_loss(&self, real: &Tensor, fake: &Tensor) -> Result<Tensor> {
        let (n_real, n_fake) = (real.dim(0)?, fake.dim(0)?);
        if real.rank() != 4 || real.dims()[1..] != fake.dims()[1..] || n_real * n_fake == 0 {
            return Err(invalid(
                "critic loss inputs",
                format!(
                    "real {:?} and fake {:?} must be non-empty (N, C, H, W) batches of the same \
                     C, H, W",
                    real.shape(),
                    fake.shape()
                ),
            ));
        }
        let maps = self.forward(&Tensor::cat(&[real, fake], 0)?)?;
        let patches = maps.elem_count() / (n_real + n_fake);
        // Each patch's weight in the loss: -1 / (its batch's patches) for real, + for fake.
        let weights: Vec<f64> = (0..n_real + n_fake)
            .map(|i| {
                if i < n_real {
                    -1.0 / (n_real * patches) as f64
                } else {
                    1.0 / (n_fake * patches) as f64
                }
            })
            .collect();
        let weights = Tensor::from_vec(weights, (n_real + n_fake, 1, 1, 1), maps.device())?
            .to_dtype(maps.dtype())?;
        Ok(maps.broadcast_mul(&weights)?.sum_all()?)
    }

    /// The WGAN-GP gradient penalty of this critic, the same value as
    /// [`gradient_penalty`](crate::gradient_penalty)`(self, ...)` (same draws from `rng`, same
    /// norm and weight), built as a first-order graph in the weights, so it needs neither
    /// `CANDLE_GRAD_DO_NOT_DETACH` nor candle's second-order bookkeeping.
    ///
    /// The critic is piecewise linear: its input gradient at the mixed images is
    /// `W_1^T M_1 W_2^T ... M_{L-1} W_L^T 1`, with `M_k` the LeakyReLU slopes of layer `k` at those
    /// images, which do not change under a small change of the weights (nor do the biases enter
    /// it). So the forward pass runs on constants and only records the slopes, and the gradient
    /// is written as a chain of transposed convolutions whose backward pass is the penalty's
    /// exact gradient: a forward convolution and a kernel gradient per layer, where the generic
    /// double backward also computes the unused weight and bias gradients of the first backward.
    /// On other devices than the CPU it is the generic function.
    ///
    /// ```
    /// use candle_core::{DType, Device, Tensor};
    /// use candle_nn::{VarBuilder, VarMap};
    /// use patch_gan::{GradientPenalty, PatchDiscriminator2d, PatchDiscriminator2dConfig};
    /// use rand::SeedableRng;
    /// let varmap = VarMap::new();
    /// let vb = VarBuilder::from_varmap(&varmap, DType::F32, &Device::Cpu);
    /// let critic = PatchDiscriminator2d::new(&PatchDiscriminator2dConfig::default().with_layers(3), vb)?;
    /// let real = Tensor::rand(0f32, 1., (2, 4, 12, 12), &Device::Cpu)?;
    /// let fake = Tensor::rand(0f32, 1., (2, 4, 12, 12), &Device::Cpu)?;
    /// let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0);
    /// let gp = critic.gradient_penalty(&real, &fake, GradientPenalty::default(), &mut rng)?;
    /// let grads = gp.backward()?;
    /// let data = varmap.data().lock().unwrap();
    /// let weights: Vec<_> = data.iter().filter(|(name, _)| name.ends_with("weight")).collect();
    /// assert_eq!(weights.len(), 3);
    /// assert!(weights.iter().all(|(_, v)| grads.get(v).is_some()));
    /// # Ok::<(), patch_gan::Error>(())
    /// ```
    pub fn gradient_penalty<R: Rng + ?Sized>(
        &self,
        real: &Tensor,
        fake: &Tensor,
        penalty: GradientPenalty,
        rng: &mut R,
    ) -> Result<Tensor> {
        if !real.device().is_cpu() {
            return crate::wgan::gradient_penalty(self, real, fake, penalty, rng);
        }
        let mixed = mixed_images(real, fake, rng)?;
        self.check_input(&mixed)?;
        // Each hidden layer's input dims and output (whose sign is the LeakyReLU branch).
        let mut layers = Vec::with_capacity(self.blocks.len());
        let mut x = mixed;
        for conv in &self.blocks {
            let convolved = op::conv2d(&x, &conv.weight().detach(), conv.config())?;
            let y = match conv.bias() {
                Some(bias) => bias_leaky_relu(&convolved, &bias.detach(), LEAKY_SLOPE)?,
                None => leaky_relu(&convolved, LEAKY_SLOPE)?,
            };
            layers.push((x.dims4()?, y.clone()));
            x = y;
        }
        let (n, _, h, w) = x.dims4()?;
        let cfg = self.tail.config();
        let (_, _, kh, kw) = self.tail.weight().dims4()?;
        let out_side = |side: usize, k: usize| (side + 2 * cfg.padding - k) / cfg.stride + 1;
        let out_dims = (n, 1, out_side(h, kh), out_side(w, kw));
        // d sum(D) / d (tail output) is all ones.
        let ones = Tensor::ones(out_dims, x.dtype(), x.device())?;
        let mut grad = op::conv2d_grad_input(&ones, self.tail.weight(), cfg, x.dims4()?)?;
        for (conv, (input_dims, output)) in self.blocks.iter().zip(layers).rev() {
            let pre = leaky_grad(&grad, &output, LEAKY_SLOPE)?;
            grad = op::conv2d_grad_input(&pre, conv.weight(), conv.config(), input_dims)?;
        }
        penalty_of_gradient(&grad, penalty)
    }

    /// Errors unless `xs` is at least the receptive field along both axes.
    fn check_input(&self, xs: &Tensor) -> Result<()> {
        let (_, _, h, w) = xs.dims4()?;
        let field = self.config.receptive_field();
        if h < field || w < field {
            return Err(invalid(
                "PatchDiscriminator2d input",
                format!("{h}x{w} is smaller than the receptive field {field}"),
            ));
        }
        Ok(())
    }
}

impl Module for PatchDiscriminator2d {
    fn forward(&self, xs: &Tensor) -> candle_core::Result<Tensor> {
        self.check_input(xs)?;
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

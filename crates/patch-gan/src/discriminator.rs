//! The patch critic: the paper's 2D critic D_n of renderings ([`PatchDiscriminator2d`]) and the
//! same network over volumes ([`PatchDiscriminator3d`], 3inGAN's 3D critic).

use candle_core::{Module, Tensor};
use candle_nn::VarBuilder;
use rand::Rng;

use crate::conv::{layer_tensors, op, ConvConfig};
use crate::error::{invalid, Result};
use crate::fused::{bias_leaky_relu, conv_bias_leaky, critic};
use crate::norm::LEAKY_SLOPE;
use crate::wgan::{draw_alphas, GradientPenalty};

/// Receptive field, in pixels (voxels) along each axis, of `layers` unpadded 3x3 (3x3x3) stride-1
/// convolutions: each layer widens it by 2, so it is `2 L + 1` (11 for L = 5, 15 for L = 7). One
/// patch-map value depends on exactly this square (cube) of the input, and the patch map is
/// `2 L` smaller than the input along each axis.
///
/// ```
/// assert_eq!(patch_gan::receptive_field(5), 11);
/// assert_eq!(patch_gan::receptive_field(7), 15);
/// ```
pub fn receptive_field(layers: usize) -> usize {
    2 * layers + 1
}

/// Shape of a [`PatchDiscriminator`]. The default is the paper's D_n for n < N with L = 5:
/// 4 input channels (RGB + depth), 32 hidden channels.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PatchDiscriminatorConfig {
    /// Number of convolution layers L, at least 2 (the paper uses 5 or 7).
    pub layers: usize,
    /// Hidden channels (32).
    pub channels: usize,
    /// Input channels: 4 (RGB + depth) for n < N, 6 (joint [G_N output, naive upsample]) at N.
    pub in_channels: usize,
}

/// The 2D critic's config under its original name.
pub type PatchDiscriminator2dConfig = PatchDiscriminatorConfig;

impl Default for PatchDiscriminatorConfig {
    fn default() -> Self {
        Self {
            layers: 5,
            channels: 32,
            in_channels: 4,
        }
    }
}

impl PatchDiscriminatorConfig {
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

/// One layer's tensors: weight `(C_out, C_in, 3, ..)` with `AXES` kernel axes and bias.
#[derive(Debug, Clone)]
struct Layer {
    weight: Tensor,
    bias: Tensor,
}

/// The patch critic over `AXES` spatial axes: `L - 1` unpadded 3x3 (3x3x3) convolutions +
/// LeakyReLU(0.2), then an unpadded convolution to one channel. Use it as
/// [`PatchDiscriminator2d`] on images `(N, C, H, W)`, mapped to the patch map
/// `(N, 1, H - 2L, W - 2L)`, or as [`PatchDiscriminator3d`] on volumes `(N, C, D, H, W)`; the
/// mean of the patch map is the critic's score ([`PatchDiscriminator::score`]).
///
/// Checkpoint names: `blocks.{i}.conv.{weight,bias}` for `i < L - 1`, and `tail.{weight,bias}`.
///
/// ```
/// use candle_core::{DType, Device, Module, Tensor};
/// use candle_nn::{VarBuilder, VarMap};
/// use patch_gan::{PatchDiscriminator2d, PatchDiscriminator3d, PatchDiscriminatorConfig};
/// let varmap = VarMap::new();
/// let vb = VarBuilder::from_varmap(&varmap, DType::F32, &Device::Cpu);
/// let d = PatchDiscriminator2d::new(&PatchDiscriminatorConfig::default(), vb.pp("d1"))?;
/// let map = d.forward(&Tensor::zeros((2, 4, 32, 32), DType::F32, &Device::Cpu)?)?;
/// assert_eq!(map.dims(), &[2, 1, 22, 22]);
/// // A 3D critic of opacity and colour volumes.
/// let cfg = PatchDiscriminatorConfig { layers: 3, channels: 8, in_channels: 4 };
/// let d3 = PatchDiscriminator3d::new(&cfg, vb.pp("d3"))?;
/// let map = d3.forward(&Tensor::zeros((1, 4, 10, 10, 10), DType::F32, &Device::Cpu)?)?;
/// assert_eq!(map.dims(), &[1, 1, 4, 4, 4]);
/// # Ok::<(), patch_gan::Error>(())
/// ```
#[derive(Debug, Clone)]
pub struct PatchDiscriminator<const AXES: usize> {
    blocks: Vec<Layer>,
    tail: Layer,
    config: PatchDiscriminatorConfig,
}

/// The paper's 2D patch critic D_n of renderings, `(N, C, H, W)`.
pub type PatchDiscriminator2d = PatchDiscriminator<2>;

/// The patch critic of volumes, `(N, C, D, H, W)`: judges 3D patches as 3inGAN's 3D critic does.
pub type PatchDiscriminator3d = PatchDiscriminator<3>;

/// Kernel size of every critic layer.
const KERNEL: usize = 3;

impl<const AXES: usize> PatchDiscriminator<AXES> {
    /// Builds (or loads) the critic's tensors under `vb`. Errors on fewer than 2 layers, zero
    /// channels, or `AXES` other than 2 and 3.
    pub fn new(config: &PatchDiscriminatorConfig, vb: VarBuilder) -> Result<Self> {
        if !(2..=3).contains(&AXES) {
            return Err(invalid(
                "PatchDiscriminator axes",
                format!("2 (images) or 3 (volumes), got {AXES}"),
            ));
        }
        if config.layers < 2 {
            return Err(invalid(
                "PatchDiscriminator layers",
                format!("need at least 2, got {}", config.layers),
            ));
        }
        if config.channels == 0 || config.in_channels == 0 {
            return Err(invalid("PatchDiscriminator channels", "must be positive"));
        }
        let layer = |c_in: usize, c_out: usize, vb: VarBuilder| -> Result<Layer> {
            match layer_tensors(c_in, c_out, KERNEL, AXES, true, vb)? {
                (weight, Some(bias)) => Ok(Layer { weight, bias }),
                (_, None) => Err(invalid("PatchDiscriminator", "a layer without bias")),
            }
        };
        let blocks = (0..config.layers - 1)
            .map(|i| {
                let c_in = if i == 0 {
                    config.in_channels
                } else {
                    config.channels
                };
                layer(c_in, config.channels, vb.pp("blocks").pp(i).pp("conv"))
            })
            .collect::<Result<Vec<_>>>()?;
        let tail = layer(config.channels, 1, vb.pp("tail"))?;
        Ok(Self {
            blocks,
            tail,
            config: *config,
        })
    }

    /// The configuration it was built with.
    pub fn config(&self) -> &PatchDiscriminatorConfig {
        &self.config
    }

    /// One score per input: the mean of the patch map, shape `(N,)`.
    pub fn score(&self, xs: &Tensor) -> Result<Tensor> {
        Ok(self.forward(xs)?.flatten_from(1)?.mean(1)?)
    }

    /// The critic's WGAN loss [`critic_loss`](crate::critic_loss)`(D(real), D(fake))`, i.e.
    /// `mean(D(fake)) - mean(D(real))` over all patches, with both batches through one forward
    /// pass (half the convolution calls, each on twice the inputs). `real` and `fake` may hold
    /// different numbers of images (volumes) of the same channels and size.
    ///
    /// On the CPU the whole critic and the loss are one op each way, on buffers the next step
    /// reuses: differentiable once (in the weights, and in `real` and `fake` where they are part
    /// of the graph); [`Module::forward`] remains for higher orders.
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
        if real.rank() != AXES + 2 || real.dims()[1..] != fake.dims()[1..] || n_real * n_fake == 0 {
            return Err(invalid(
                "critic loss inputs",
                format!(
                    "real {:?} and fake {:?} must be non-empty batches (N, C, ..) with {AXES} \
                     spatial axes, of the same channels and size",
                    real.shape(),
                    fake.shape()
                ),
            ));
        }
        if real.device().is_cpu() {
            self.check_input(real)?;
            let params = critic::pack_interleaved(&self.kernels()?, &self.biases())?;
            let inputs = (&Self::lift(real)?, &Self::lift(fake)?);
            return Ok(critic::critic_loss(inputs, &params, &self.layers()?)?);
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
        let mut weight_shape = vec![1; maps.rank()];
        weight_shape[0] = n_real + n_fake;
        let weights =
            Tensor::from_vec(weights, weight_shape, maps.device())?.to_dtype(maps.dtype())?;
        Ok(maps.broadcast_mul(&weights)?.sum_all()?)
    }

    /// The WGAN-GP gradient penalty of this critic, the same value as
    /// [`gradient_penalty`](crate::gradient_penalty)`(self, ...)` (same draws from `rng`, same
    /// norm and weight), built as a first-order graph in the weights, so it needs neither
    /// `CANDLE_GRAD_DO_NOT_DETACH` nor candle's second-order bookkeeping.
    ///
    /// The critic is piecewise linear: its input gradient at the mixed inputs is
    /// `W_1^T M_1 W_2^T ... M_{L-1} W_L^T 1`, with `M_k` the LeakyReLU slopes of layer `k` at those
    /// inputs, which do not change under a small change of the weights (nor do the biases enter
    /// it). So the forward pass runs on constants and only records the slopes, and the gradient
    /// is a chain of transposed convolutions whose backward pass is the penalty's exact
    /// gradient: a forward convolution and a kernel gradient per layer, where the generic
    /// double backward also computes the unused weight and bias gradients of the first backward.
    /// The mixing, the layers, the chain and the penalty are one op each way, on buffers the
    /// next step reuses; the biases get no gradient from it. On other devices than the CPU it is
    /// the generic function.
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
        let alphas = draw_alphas(real, fake, rng)?;
        self.check_input(real)?;
        let params = critic::pack_weights_first(&self.kernels()?, &self.biases())?;
        let inputs = (&Self::lift(real)?, &Self::lift(fake)?);
        Ok(critic::penalty(
            inputs,
            alphas,
            &params,
            (&self.layers()?, penalty),
        )?)
    }

    /// Every layer's kernel as the 3D convolution op takes it ([`Self::kernel_3d`]).
    fn kernels(&self) -> Result<Vec<Tensor>> {
        self.blocks
            .iter()
            .chain([&self.tail])
            .map(|layer| Self::kernel_3d(&layer.weight))
            .collect()
    }

    /// Every layer's bias.
    fn biases(&self) -> Vec<&Tensor> {
        self.blocks
            .iter()
            .chain([&self.tail])
            .map(|layer| &layer.bias)
            .collect()
    }

    /// The layers as the fused critic ops take them.
    fn layers(&self) -> Result<critic::Layers> {
        let kernels = self
            .kernels()?
            .iter()
            .map(|k| match *k.dims() {
                [c_out, c_in, kd, kh, kw] => Ok([c_out, c_in, kd, kh, kw]),
                _ => Err(invalid("PatchDiscriminator", "a kernel that is not 3D")),
            })
            .collect::<Result<_>>()?;
        Ok(critic::Layers {
            kernels,
            slope: LEAKY_SLOPE,
        })
    }

    /// The critic's inputs as the layers take them: on the CPU, images get a depth axis of 1 once
    /// (volumes are as they are), so that every layer runs the 3D convolution op on them without
    /// a reshape of its own. Each reshape is a node of the graph, and candle's backward pass
    /// accumulates a gradient for every node into a fresh zero tensor: without the two reshapes
    /// per layer each way a critic step with its penalty is 3-6% faster at 54^2 and 108^2.
    fn lift(xs: &Tensor) -> Result<Tensor> {
        Ok(if AXES == 2 && xs.device().is_cpu() {
            xs.unsqueeze(2)?
        } else {
            xs.clone()
        })
    }

    /// The critic's output with the axes of its input: the inverse of [`Self::lift`].
    fn lower(ys: &Tensor) -> Result<Tensor> {
        Ok(if ys.rank() == AXES + 3 {
            ys.squeeze(2)?
        } else {
            ys.clone()
        })
    }

    /// `weight` as the kernel of the 3D convolution op: images' kernels get a depth axis of 1.
    fn kernel_3d(weight: &Tensor) -> Result<Tensor> {
        Ok(if weight.rank() == 4 {
            weight.unsqueeze(2)?
        } else {
            weight.clone()
        })
    }

    /// The unpadded stride-1 convolution of the critic's layers over `AXES` axes, of an input as
    /// [`Self::lift`] leaves it.
    fn conv(xs: &Tensor, weight: &Tensor) -> Result<Tensor> {
        if xs.rank() == 4 {
            op::conv2d(xs, weight, ConvConfig::default())
        } else {
            op::conv3d(xs, &Self::kernel_3d(weight)?, ConvConfig::default())
        }
    }

    /// Errors unless `xs` has `AXES` spatial axes, each at least the receptive field.
    fn check_input(&self, xs: &Tensor) -> Result<()> {
        let field = self.config.receptive_field();
        let what = if AXES == 2 { "images" } else { "volumes" };
        if xs.rank() != AXES + 2 {
            return Err(invalid(
                "PatchDiscriminator input",
                format!(
                    "expected {what} with {AXES} spatial axes, got {:?}",
                    xs.shape()
                ),
            ));
        }
        if xs.dims()[2..].iter().any(|&side| side < field) {
            return Err(invalid(
                "PatchDiscriminator input",
                format!(
                    "{:?} is smaller than the receptive field {field} along an axis",
                    &xs.dims()[2..]
                ),
            ));
        }
        Ok(())
    }
}

impl<const AXES: usize> Module for PatchDiscriminator<AXES> {
    fn forward(&self, xs: &Tensor) -> candle_core::Result<Tensor> {
        self.check_input(xs)?;
        let mut x = Self::lift(xs).map_err(candle_core::Error::wrap)?;
        for layer in &self.blocks {
            x = if x.rank() == 5 && x.device().is_cpu() {
                // One op: no graph node (and gradient accumulation) for the convolution.
                let kernel = Self::kernel_3d(&layer.weight)?;
                let cfg = ConvConfig::default();
                conv_bias_leaky(&x, &kernel, cfg, &layer.bias, LEAKY_SLOPE)?
            } else {
                bias_leaky_relu(&Self::conv(&x, &layer.weight)?, &layer.bias, LEAKY_SLOPE)?
            };
        }
        let ys = crate::fused::bias_add(&Self::conv(&x, &self.tail.weight)?, &self.tail.bias)?;
        Ok(Self::lower(&ys)?)
    }
}

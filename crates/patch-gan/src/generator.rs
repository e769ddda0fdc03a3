//! `Generator3d`: the paper's L-layer 3D convolutional generator G_n (n < N).

use std::sync::Arc;

use candle_core::{ModuleT, Tensor};
use candle_nn::{Module, VarBuilder};

use crate::active::{self, ActiveSites};
use crate::conv::op::Domain;
use crate::conv::{conv3d, op, Conv3d, ConvConfig};
use crate::error::{invalid, Result};
use crate::fused::{bias_add, conv_norm_stack};
use crate::norm::{batch_norm3d, BatchNorm3d, LEAKY_SLOPE, NORM_EPS};

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
        if self.kernel.is_multiple_of(2) {
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
        self.check_residual(z, prev_up)?;
        let residual = self.forward_t(&(z + prev_up)?, train)?;
        Ok((prev_up + residual)?)
    }

    /// The residual form on the active sites only: `prev_up + S(G_A(z + prev_up))`, where `G_A`
    /// is the generator run as submanifold layers on `sites` (each convolution computes the
    /// active sites only and reads inactive voxels as zero; BatchNorm takes its statistics over
    /// the active sites of the batch) and `S` scatters its output to the sites' voxels. Outside
    /// the active set the volume stays `prev_up`, and no gradient reaches the generator from
    /// there. With `A` the mask of the sites, this is the dense generator with its input and
    /// every layer's output multiplied by `A` and BatchNorm statistics over `A`'s voxels
    /// ([`Generator3d::forward_residual_active_dense`], which other devices than the CPU run);
    /// on the CPU it costs in proportion to the active sites. An empty set returns `prev_up`.
    ///
    /// ```
    /// use std::sync::Arc;
    /// use candle_core::{DType, Device, Tensor};
    /// use candle_nn::{VarBuilder, VarMap};
    /// use patch_gan::{ActiveSites, Generator3d, Generator3dConfig};
    /// let dev = Device::Cpu;
    /// let varmap = VarMap::new();
    /// let vb = VarBuilder::from_varmap(&varmap, DType::F32, &dev);
    /// let g2 = Generator3d::new(&Generator3dConfig::for_scale(2, 5), vb.pp("g2"))?;
    /// let z = Tensor::randn(0f32, 1., (1, 4, 6, 6, 6), &dev)?;
    /// let prev_up = Tensor::zeros((1, 4, 6, 6, 6), DType::F32, &dev)?;
    /// // The lower half of the box is active.
    /// let mask = Tensor::cat(&[Tensor::ones((1, 1, 3, 6, 6), DType::F32, &dev)?,
    ///                          Tensor::zeros((1, 1, 3, 6, 6), DType::F32, &dev)?], 2)?;
    /// let sites = Arc::new(ActiveSites::from_mask(&mask, 3)?);
    /// let v = g2.forward_residual_active(&z, &prev_up, &sites, true)?;
    /// // The upper half is left as it was.
    /// assert_eq!(v.narrow(2, 3, 3)?.abs()?.sum_all()?.to_scalar::<f32>()?, 0.0);
    /// # Ok::<(), patch_gan::Error>(())
    /// ```
    pub fn forward_residual_active(
        &self,
        z: &Tensor,
        prev_up: &Tensor,
        sites: &Arc<ActiveSites>,
        train: bool,
    ) -> Result<Tensor> {
        let Some(input) = self.active_input(z, prev_up, sites)? else {
            return Ok(prev_up.clone());
        };
        if !prev_up.device().is_cpu() {
            return self.forward_residual_active_dense(z, prev_up, sites, train);
        }
        let h = active::gather(&input, sites)?;
        let residual = if train {
            self.forward_stack(&h, Domain::active(sites))?
        } else {
            let mut h = h;
            for (conv, bn) in &self.blocks {
                let convolved = op::conv3d_active(&h, conv.weight(), sites)?;
                h = bn.forward_activated(&convolved, conv.bias(), LEAKY_SLOPE, train)?;
            }
            let residual = op::conv3d_active(&h, self.tail.weight(), sites)?;
            match self.tail.bias() {
                Some(bias) => bias_add(&residual, bias)?,
                None => residual,
            }
        };
        Ok((prev_up + active::scatter(&residual, sites)?)?)
    }

    /// The math of [`Generator3d::forward_residual_active`] computed densely, with candle ops and
    /// the dense convolution: the input and every layer's output multiplied by the sites' mask,
    /// BatchNorm's statistics taken over the mask's voxels (its running statistics are not
    /// updated). It costs as much as the dense generator; devices other than the CPU, which
    /// have no kernel on active sites, run it in place of the sparse form.
    ///
    /// ```
    /// use std::sync::Arc;
    /// use candle_core::{DType, Device, Tensor};
    /// use candle_nn::{VarBuilder, VarMap};
    /// use patch_gan::{ActiveSites, Generator3d, Generator3dConfig};
    /// let dev = Device::Cpu;
    /// let vb = VarBuilder::from_varmap(&VarMap::new(), DType::F32, &dev);
    /// let g2 = Generator3d::new(&Generator3dConfig::for_scale(2, 3), vb)?;
    /// let z = Tensor::randn(0f32, 1., (1, 4, 5, 5, 5), &dev)?;
    /// let prev_up = Tensor::randn(0f32, 1., (1, 4, 5, 5, 5), &dev)?;
    /// let active: Vec<bool> = (0..125).map(|i| i % 3 != 0).collect();
    /// let sites = Arc::new(ActiveSites::new(1, [5, 5, 5], 3, &active)?);
    /// let sparse = g2.forward_residual_active(&z, &prev_up, &sites, true)?;
    /// let dense = g2.forward_residual_active_dense(&z, &prev_up, &sites, true)?;
    /// let diff = (sparse - dense)?.abs()?.flatten_all()?.max(0)?.to_scalar::<f32>()?;
    /// assert!(diff < 1e-4);
    /// # Ok::<(), patch_gan::Error>(())
    /// ```
    pub fn forward_residual_active_dense(
        &self,
        z: &Tensor,
        prev_up: &Tensor,
        sites: &Arc<ActiveSites>,
        train: bool,
    ) -> Result<Tensor> {
        let Some(input) = self.active_input(z, prev_up, sites)? else {
            return Ok(prev_up.clone());
        };
        let mask = sites.mask(prev_up.dtype(), prev_up.device())?;
        let count = sites.len() as f64;
        let mut h = input.broadcast_mul(&mask)?;
        for (conv, bn) in &self.blocks {
            let convolved = conv.forward(&h)?;
            h = bn
                .masked_forward(&convolved, &mask, count, LEAKY_SLOPE, train)?
                .broadcast_mul(&mask)?;
        }
        let residual = self.tail.forward(&h)?.broadcast_mul(&mask)?;
        Ok((prev_up + residual)?)
    }

    /// The generator's input `z + prev_up` for the two active-set forms, after their checks
    /// (the residual's shapes, `sites` built for these volumes and this generator's kernel), or
    /// `None` when no site is active (the volume stays `prev_up`).
    fn active_input(
        &self,
        z: &Tensor,
        prev_up: &Tensor,
        sites: &ActiveSites,
    ) -> Result<Option<Tensor>> {
        self.check_residual(z, prev_up)?;
        sites.check_volumes("Generator3d active sites", prev_up)?;
        if sites.kernel() != self.config.kernel {
            return Err(invalid(
                "Generator3d active sites",
                format!(
                    "built for kernel {}, the generator's is {}",
                    sites.kernel(),
                    self.config.kernel
                ),
            ));
        }
        if sites.is_empty() {
            return Ok(None);
        }
        Ok(Some((z + prev_up)?))
    }

    /// Checks what both residual forms need: `in_channels == out_channels` and `z`, `prev_up`
    /// of one shape.
    fn check_residual(&self, z: &Tensor, prev_up: &Tensor) -> Result<()> {
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
        Ok(())
    }
}

impl Generator3d {
    /// The generator in training mode on the CPU, its convolutions in `domain` (the grid, or
    /// active sites): every layer in one op (the same kernels and bits as layer by layer; see
    /// [`crate::fused::conv_norm_stack`]), then the last layer's bias. The blocks'
    /// convolutions have biases that batch statistics cancel: they go to the running means only.
    fn forward_stack(&self, xs: &Tensor, domain: Domain) -> candle_core::Result<Tensor> {
        let blocks: Vec<_> = self
            .blocks
            .iter()
            .map(|(conv, bn)| bn.stack_block(conv.weight()))
            .collect();
        let eps_slope = (NORM_EPS, LEAKY_SLOPE);
        let (ys, stats) = conv_norm_stack(xs, &blocks, self.tail.weight(), domain, eps_slope)?;
        for ((conv, bn), stats) in self.blocks.iter().zip(stats) {
            bn.record(stats, conv.bias())?;
        }
        match self.tail.bias() {
            Some(bias) => bias_add(&ys, bias),
            None => Ok(ys),
        }
    }
}

impl ModuleT for Generator3d {
    fn forward_t(&self, xs: &Tensor, train: bool) -> candle_core::Result<Tensor> {
        if train && xs.device().is_cpu() {
            // One configuration for all layers, as `Generator3d::new` builds them.
            let cfg = self.tail.config();
            debug_assert!(self.blocks.iter().all(|(conv, _)| conv.config() == cfg));
            return self.forward_stack(xs, Domain::grid(cfg));
        }
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

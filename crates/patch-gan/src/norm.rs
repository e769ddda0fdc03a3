//! Normalisation layers: `BatchNorm3d` (train and eval) and `InstanceNorm2d`.

use candle_core::{DType, ModuleT, Tensor, Var};
use candle_nn::{Init, Module, VarBuilder};

use crate::error::{invalid, Result};
pub use crate::fused::leaky_relu;
use crate::fused::{batch_norm_act, BatchStats, NormStats, StackBlock};

/// PyTorch's default `eps` for both normalisations.
pub const NORM_EPS: f64 = 1e-5;

/// Batch normalisation of `(N, C, D, H, W)` volumes over N, D, H, W per channel, as PyTorch's
/// `nn.BatchNorm3d(C)` with its defaults: eps 1e-5, momentum 0.1, affine, tracked running stats.
///
/// In train mode (`forward_t(x, true)`) it normalises with the batch statistics (biased variance)
/// and updates `running_mean = 0.9 running_mean + 0.1 mean`, `running_var = 0.9 running_var +
/// 0.1 unbiased_var`; in eval mode it uses the running statistics. Tensors are named `weight`,
/// `bias`, `running_mean`, `running_var` as in a PyTorch state dict; new ones start at 1, 0, 0, 1.
///
/// ```
/// use candle_core::{DType, Device, ModuleT, Tensor};
/// use candle_nn::{VarBuilder, VarMap};
/// let varmap = VarMap::new();
/// let vb = VarBuilder::from_varmap(&varmap, DType::F32, &Device::Cpu);
/// let bn = patch_gan::batch_norm3d(2, vb.pp("bn"))?;
/// let x = Tensor::arange(0f32, 16., &Device::Cpu)?.reshape((1, 2, 2, 2, 2))?;
/// let y = bn.forward_t(&x, true)?;
/// assert_eq!(y.dims(), x.dims());
/// # Ok::<(), patch_gan::Error>(())
/// ```
///
/// On the CPU the normalisation and an optional LeakyReLU after it run as one fused op
/// ([`BatchNorm3d::forward_activated`], which the generators use); other devices run candle ops.
#[derive(Debug, Clone)]
pub struct BatchNorm3d {
    weight: Tensor,
    bias: Tensor,
    running_mean: Var,
    running_var: Var,
}

/// PyTorch's default momentum of the running statistics.
const MOMENTUM: f64 = 0.1;

impl BatchNorm3d {
    /// The running mean, `(C,)`.
    pub fn running_mean(&self) -> &Tensor {
        self.running_mean.as_tensor()
    }

    /// The running (unbiased) variance, `(C,)`.
    pub fn running_var(&self) -> &Tensor {
        self.running_var.as_tensor()
    }

    /// `LeakyReLU(BatchNorm(xs + input_bias))` with the given negative slope (1 is no
    /// activation), `input_bias` `(C,)` being the bias of the convolution before this layer.
    ///
    /// In train mode the batch statistics absorb any per-channel constant, so the bias changes
    /// neither the output nor (being then exactly without gradient) the loss: it is only folded
    /// into the running mean, where PyTorch's convolution + BatchNorm would leave it, and the
    /// convolution saves adding it. In eval mode it is added to the input.
    ///
    /// ```
    /// use candle_core::{DType, Device, ModuleT, Tensor};
    /// use candle_nn::{VarBuilder, VarMap};
    /// let varmap = VarMap::new();
    /// let vb = VarBuilder::from_varmap(&varmap, DType::F32, &Device::Cpu);
    /// let bn = patch_gan::batch_norm3d(2, vb.pp("bn"))?;
    /// let x = Tensor::arange(0f32, 16., &Device::Cpu)?.reshape((1, 2, 2, 2, 2))?;
    /// let bias = Tensor::new(&[5f32, -5.], &Device::Cpu)?;
    /// let fused = bn.forward_activated(&x, Some(&bias), 0.2, true)?;
    /// let plain = patch_gan::leaky_relu(&bn.forward_t(&x, true)?, 0.2)?;
    /// let diff = (fused - plain)?.abs()?.flatten_all()?.max(0)?.to_scalar::<f32>()?;
    /// assert!(diff < 1e-6);
    /// # Ok::<(), candle_core::Error>(())
    /// ```
    pub fn forward_activated(
        &self,
        xs: &Tensor,
        input_bias: Option<&Tensor>,
        negative_slope: f64,
        train: bool,
    ) -> candle_core::Result<Tensor> {
        if xs.rank() != 5 {
            return Err(invalid(
                "BatchNorm3d input",
                format!("expected (N, C, D, H, W), got {:?}", xs.shape()),
            )
            .into());
        }
        let channels = self.weight.dim(0)?;
        let with_bias = |xs: &Tensor| match input_bias {
            Some(b) => xs.broadcast_add(&b.reshape((1, channels, 1, 1, 1))?),
            None => Ok(xs.clone()),
        };
        if !xs.device().is_cpu() {
            return leaky_relu(
                &self.candle_forward(&with_bias(xs)?, train)?,
                negative_slope,
            );
        }
        if !train {
            let stats = NormStats::Running {
                mean: to_f64(self.running_mean())?,
                var: to_f64(self.running_var())?,
            };
            let xs = with_bias(xs)?;
            let (ys, _) = batch_norm_act(
                &xs,
                &self.weight,
                &self.bias,
                stats,
                NORM_EPS,
                negative_slope,
            )?;
            return Ok(ys);
        }
        let (ys, stats) = batch_norm_act(
            xs,
            &self.weight,
            &self.bias,
            NormStats::Batch,
            NORM_EPS,
            negative_slope,
        )?;
        self.record(stats, input_bias)?;
        Ok(ys)
    }

    /// This layer as a block of a [`crate::fused::conv_norm_stack`] after a convolution by
    /// `kernel`: the training-mode generators run all their layers as one op.
    pub(crate) fn stack_block<'a>(&'a self, kernel: &'a Tensor) -> StackBlock<'a> {
        StackBlock {
            kernel,
            gamma: &self.weight,
            beta: &self.bias,
        }
    }

    /// Folds a train-mode pass's batch statistics into the running ones; the batch's mean is
    /// taken after `input_bias` (PyTorch's convolution would have added it).
    pub(crate) fn record(
        &self,
        stats: Option<BatchStats>,
        input_bias: Option<&Tensor>,
    ) -> candle_core::Result<()> {
        let Some(stats) = stats else { return Ok(()) };
        let shift = match input_bias {
            Some(b) => to_f64(b)?,
            None => vec![0.0; stats.mean.len()],
        };
        let mean: Vec<f64> = stats.mean.iter().zip(&shift).map(|(m, b)| m + b).collect();
        let unbiased = stats.count as f64 / (stats.count.max(2) - 1) as f64;
        let var: Vec<f64> = stats.var.iter().map(|v| v * unbiased).collect();
        self.update_running(&mean, &var)
    }

    /// `running = (1 - momentum) running + momentum batch` for both statistics.
    fn update_running(&self, mean: &[f64], var: &[f64]) -> candle_core::Result<()> {
        for (running, batch) in [(&self.running_mean, mean), (&self.running_var, var)] {
            let old = to_f64(running.as_tensor())?;
            let new: Vec<f64> = old
                .iter()
                .zip(batch)
                .map(|(o, b)| (1.0 - MOMENTUM) * o + MOMENTUM * b)
                .collect();
            let dev = running.device();
            running.set(&Tensor::from_vec(new, batch.len(), dev)?.to_dtype(running.dtype())?)?;
        }
        Ok(())
    }

    /// `LeakyReLU(BatchNorm(xs))` with the batch statistics taken over the voxels where `mask`
    /// `(N, 1, D, H, W)` is 1 (`count` of them), in candle ops: the dense form of the layer on
    /// active sites (see [`crate::Generator3d::forward_residual_active_dense`]). Eval mode uses
    /// the running statistics; like [`BatchNorm3d::candle_forward`] it does not update them.
    pub(crate) fn masked_forward(
        &self,
        xs: &Tensor,
        mask: &Tensor,
        count: f64,
        negative_slope: f64,
        train: bool,
    ) -> candle_core::Result<Tensor> {
        let per_channel = |t: &Tensor| t.reshape((1, (), 1, 1, 1));
        let channel_sum = |t: &Tensor| {
            t.sum_keepdim(4)?
                .sum_keepdim(3)?
                .sum_keepdim(2)?
                .sum_keepdim(0)
        };
        let (centred, var) = if train {
            let mean = (channel_sum(&xs.broadcast_mul(mask)?)? / count)?;
            let centred = xs.broadcast_sub(&mean)?;
            let var = (channel_sum(&centred.broadcast_mul(mask)?.sqr()?)? / count)?;
            (centred, var)
        } else {
            (
                xs.broadcast_sub(&per_channel(self.running_mean())?)?,
                per_channel(self.running_var())?,
            )
        };
        leaky_relu(&self.scale_centred(&centred, &var)?, negative_slope)
    }

    /// The same layer in candle ops, for devices without the fused kernel (running statistics are
    /// updated by the CPU path only).
    fn candle_forward(&self, xs: &Tensor, train: bool) -> candle_core::Result<Tensor> {
        let per_channel = |t: &Tensor| t.reshape((1, (), 1, 1, 1));
        // The centred input is made once and serves the variance and the output (candle keeps
        // every intermediate until the backward pass).
        let (centred, var) = if train {
            let mean = xs
                .mean_keepdim(4)?
                .mean_keepdim(3)?
                .mean_keepdim(2)?
                .mean_keepdim(0)?;
            let centred = xs.broadcast_sub(&mean)?;
            let var = centred
                .sqr()?
                .mean_keepdim(4)?
                .mean_keepdim(3)?
                .mean_keepdim(2)?
                .mean_keepdim(0)?;
            (centred, var)
        } else {
            (
                xs.broadcast_sub(&per_channel(self.running_mean())?)?,
                per_channel(self.running_var())?,
            )
        };
        self.scale_centred(&centred, &var)
    }

    /// `centred * weight / sqrt(var + eps) + bias` for the candle-op forms. Built for memory,
    /// as candle keeps every intermediate until the backward pass: the weight and the
    /// deviation meet per channel, so two tensors of the input's size are made here where
    /// dividing and scaling the input in turn made four.
    fn scale_centred(&self, centred: &Tensor, var: &Tensor) -> candle_core::Result<Tensor> {
        let per_channel = |t: &Tensor| t.reshape((1, (), 1, 1, 1));
        let scale = per_channel(&self.weight)?.broadcast_div(&(var + NORM_EPS)?.sqrt()?)?;
        centred
            .broadcast_mul(&scale)?
            .broadcast_add(&per_channel(&self.bias)?)
    }
}

/// A small tensor's values as f64.
fn to_f64(t: &Tensor) -> candle_core::Result<Vec<f64>> {
    t.to_dtype(DType::F64)?.to_vec1::<f64>()
}

impl ModuleT for BatchNorm3d {
    fn forward_t(&self, xs: &Tensor, train: bool) -> candle_core::Result<Tensor> {
        self.forward_activated(xs, None, 1.0, train)
    }
}

/// A [`BatchNorm3d`] over `channels` channels reading or creating its four tensors under `vb`.
pub fn batch_norm3d(channels: usize, vb: VarBuilder) -> Result<BatchNorm3d> {
    if channels == 0 {
        return Err(invalid("BatchNorm3d channels", "must be positive"));
    }
    let running_mean = vb.get_with_hints(channels, "running_mean", Init::Const(0.))?;
    let running_var = vb.get_with_hints(channels, "running_var", Init::Const(1.))?;
    Ok(BatchNorm3d {
        weight: vb.get_with_hints(channels, "weight", Init::Const(1.))?,
        bias: vb.get_with_hints(channels, "bias", Init::Const(0.))?,
        // The variables of the VarMap themselves (from_tensor of a variable shares its storage),
        // so updating them updates what a checkpoint saves.
        running_mean: Var::from_tensor(&running_mean)?,
        running_var: Var::from_tensor(&running_var)?,
    })
}

/// Instance normalisation of `(N, C, H, W)` images: each `(n, c)` plane is shifted to mean 0 and
/// scaled to (biased) variance 1, `y = (x - mean) / sqrt(var + eps)`. This is PyTorch's
/// `nn.InstanceNorm2d(C)` with its defaults: no affine parameters and no running statistics, so
/// train and eval are the same and there is nothing to load.
///
/// ```
/// use candle_core::{Device, Module, Tensor};
/// let x = Tensor::new(&[[[[1f32, 3.], [5., 7.]]]], &Device::Cpu)?;
/// let y = patch_gan::InstanceNorm2d::default().forward(&x)?;
/// assert!(y.mean_all()?.to_scalar::<f32>()?.abs() < 1e-6);
/// # Ok::<(), candle_core::Error>(())
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct InstanceNorm2d {
    /// Added to the variance before the square root.
    pub eps: f64,
}

impl Default for InstanceNorm2d {
    fn default() -> Self {
        Self { eps: NORM_EPS }
    }
}

impl InstanceNorm2d {
    /// `LeakyReLU_slope(InstanceNorm2d(xs))` (`slope = 1` is the normalisation alone). On the
    /// CPU this is one fused op each way (the batch-statistics BatchNorm kernel with every
    /// `(n, c)` plane as a channel, unit scale and zero shift), differentiable once; elsewhere,
    /// and for gradients of gradients, use [`Module::forward`] and [`leaky_relu`].
    ///
    /// ```
    /// use candle_core::{Device, Module, Tensor};
    /// let x = Tensor::arange(0f32, 24., &Device::Cpu)?.sqr()?.reshape((2, 3, 2, 2))?;
    /// let norm = patch_gan::InstanceNorm2d::default();
    /// let fused = norm.forward_activated(&x, 0.2)?;
    /// let plain = patch_gan::leaky_relu(&norm.forward(&x)?, 0.2)?;
    /// let diff = (fused - plain)?.abs()?.flatten_all()?.max(0)?.to_scalar::<f32>()?;
    /// assert!(diff < 1e-5);
    /// # Ok::<(), candle_core::Error>(())
    /// ```
    pub fn forward_activated(
        &self,
        xs: &Tensor,
        negative_slope: f64,
    ) -> candle_core::Result<Tensor> {
        if !xs.device().is_cpu() {
            return leaky_relu(&self.forward(xs)?, negative_slope);
        }
        let (n, c, h, w) = xs.dims4()?;
        let planes = n * c;
        let unit = Tensor::ones(planes, xs.dtype(), xs.device())?;
        let zero = Tensor::zeros(planes, xs.dtype(), xs.device())?;
        let (ys, _) = batch_norm_act(
            &xs.reshape((1, planes, h * w))?,
            &unit,
            &zero,
            NormStats::Batch,
            self.eps,
            negative_slope,
        )?;
        ys.reshape((n, c, h, w))
    }
}

impl Module for InstanceNorm2d {
    fn forward(&self, xs: &Tensor) -> candle_core::Result<Tensor> {
        let (n, c, h, w) = xs.dims4()?;
        let planes = xs.reshape((n, c, h * w))?;
        let centred = planes.broadcast_sub(&planes.mean_keepdim(2)?)?;
        let var = centred.sqr()?.mean_keepdim(2)?;
        centred
            .broadcast_div(&(var + self.eps)?.sqrt()?)?
            .reshape((n, c, h, w))
    }
}

/// The LeakyReLU slope of every SinGRAV network.
pub const LEAKY_SLOPE: f64 = 0.2;

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::{DType, Device};
    use candle_nn::VarMap;

    fn input() -> Tensor {
        let n = 2 * 3 * 2 * 2 * 3;
        let v: Vec<f64> = (0..n).map(|i| ((i * 37 % 17) as f64 - 8.0) / 3.0).collect();
        Tensor::from_vec(v, (2, 3, 2, 2, 3), &Device::Cpu).unwrap()
    }

    /// Per-channel mean and biased variance over N, D, H, W, in float64.
    fn channel_stats(x: &Tensor) -> Vec<(f64, f64)> {
        let xt = x.transpose(0, 1).unwrap().flatten_from(1).unwrap();
        xt.to_vec2::<f64>()
            .unwrap()
            .iter()
            .map(|c| {
                let m = c.iter().sum::<f64>() / c.len() as f64;
                let v = c.iter().map(|x| (x - m).powi(2)).sum::<f64>() / c.len() as f64;
                (m, v)
            })
            .collect()
    }

    #[test]
    fn batch_norm_train_normalises_and_updates_running_stats() {
        let varmap = VarMap::new();
        let vb = VarBuilder::from_varmap(&varmap, DType::F64, &Device::Cpu);
        let bn = batch_norm3d(3, vb).unwrap();
        let x = input();
        let y = bn.forward_t(&x, true).unwrap();
        for (m, v) in channel_stats(&y) {
            assert!(
                m.abs() < 1e-12 && (v - 1.0).abs() < 1e-4,
                "mean {m} var {v}"
            );
        }
        let count = (2 * 2 * 2 * 3) as f64;
        let stats = channel_stats(&x);
        let rm = bn.running_mean().to_vec1::<f64>().unwrap();
        let rv = bn.running_var().to_vec1::<f64>().unwrap();
        for (c, (m, v)) in stats.iter().enumerate() {
            assert!((rm[c] - 0.1 * m).abs() < 1e-12);
            assert!((rv[c] - (0.9 + 0.1 * v * count / (count - 1.0))).abs() < 1e-12);
        }
        // The running stats live in the VarMap, so a checkpoint saves them.
        let saved = varmap.data().lock().unwrap()["running_mean"]
            .to_vec1::<f64>()
            .unwrap();
        assert_eq!(saved, rm);
    }

    /// The candle-op forms other devices run (BatchNorm on batch statistics, then LeakyReLU by
    /// ops) give the fused CPU layer's values and gradients, in f64 on the CPU.
    #[test]
    fn candle_op_forms_match_the_fused_layer() {
        let varmap = VarMap::new();
        let vb = VarBuilder::from_varmap(&varmap, DType::F64, &Device::Cpu);
        let bn = batch_norm3d(3, vb).unwrap();
        {
            let vars = varmap.data().lock().unwrap();
            let set = |name: &str, v: &[f64]| {
                vars[name]
                    .set(&Tensor::new(v, &Device::Cpu).unwrap())
                    .unwrap()
            };
            set("weight", &[0.5, -1.5, 2.0]);
            set("bias", &[0.1, 0.0, -0.3]);
        }
        let x = candle_core::Var::from_tensor(&input()).unwrap();
        let fused = bn
            .forward_activated(x.as_tensor(), None, 0.2, true)
            .unwrap();
        let by_ops =
            crate::fused::leaky_relu_by_ops(&bn.candle_forward(x.as_tensor(), true).unwrap(), 0.2)
                .unwrap();
        let probe = Tensor::rand(-1f64, 1., fused.shape(), &Device::Cpu).unwrap();
        let flat = |t: &Tensor| t.flatten_all().unwrap().to_vec1::<f64>().unwrap();
        let diff =
            |a: &[f64], b: &[f64]| a.iter().zip(b).fold(0f64, |m, (x, y)| m.max((x - y).abs()));
        assert!(diff(&flat(&fused), &flat(&by_ops)) < 1e-12);
        let g_fused = (&fused * &probe)
            .unwrap()
            .sum_all()
            .unwrap()
            .backward()
            .unwrap();
        let g_ops = (&by_ops * &probe)
            .unwrap()
            .sum_all()
            .unwrap()
            .backward()
            .unwrap();
        for var in [x.as_tensor(), &bn.weight, &bn.bias] {
            let (a, b) = (
                flat(g_fused.get(var).unwrap()),
                flat(g_ops.get(var).unwrap()),
            );
            assert!(diff(&a, &b) < 1e-10, "gradient differs by {}", diff(&a, &b));
        }
    }

    #[test]
    fn batch_norm_eval_uses_running_stats() {
        let dev = Device::Cpu;
        let mut ts = std::collections::HashMap::new();
        ts.insert(
            "weight".to_string(),
            Tensor::new(&[2f64, 1., 1.], &dev).unwrap(),
        );
        ts.insert(
            "bias".to_string(),
            Tensor::new(&[1f64, 0., 0.], &dev).unwrap(),
        );
        ts.insert(
            "running_mean".to_string(),
            Tensor::new(&[0.5f64, 0., 0.], &dev).unwrap(),
        );
        ts.insert(
            "running_var".to_string(),
            Tensor::new(&[4f64, 1., 1.], &dev).unwrap(),
        );
        let bn = batch_norm3d(3, VarBuilder::from_tensors(ts, DType::F64, &dev)).unwrap();
        let x = input();
        let y = bn.forward_t(&x, false).unwrap();
        let x0 = x
            .narrow(1, 0, 1)
            .unwrap()
            .flatten_all()
            .unwrap()
            .to_vec1::<f64>()
            .unwrap();
        let y0 = y
            .narrow(1, 0, 1)
            .unwrap()
            .flatten_all()
            .unwrap()
            .to_vec1::<f64>()
            .unwrap();
        for (a, b) in x0.iter().zip(&y0) {
            assert!((b - (2.0 * (a - 0.5) / (4.0 + NORM_EPS).sqrt() + 1.0)).abs() < 1e-12);
        }
        assert!(bn.forward_t(&x.flatten_from(3).unwrap(), false).is_err());
    }

    #[test]
    fn instance_norm_normalises_each_plane() {
        let x = input().reshape((2, 3, 4, 3)).unwrap();
        let y = InstanceNorm2d::default().forward(&x).unwrap();
        for plane in y
            .flatten_from(2)
            .unwrap()
            .flatten_to(1)
            .unwrap()
            .to_vec2::<f64>()
            .unwrap()
        {
            let m = plane.iter().sum::<f64>() / plane.len() as f64;
            let v = plane.iter().map(|x| (x - m).powi(2)).sum::<f64>() / plane.len() as f64;
            assert!(
                m.abs() < 1e-12 && (v - 1.0).abs() < 1e-3,
                "mean {m} var {v}"
            );
        }
    }

    /// The fused instance norm + LeakyReLU equals the candle-op composition in f64, values and
    /// the input's gradient (the composition is checked against the definition elsewhere).
    #[test]
    fn fused_instance_norm_matches_the_composition() {
        let x = candle_core::Var::from_tensor(&input().reshape((2, 3, 4, 3)).unwrap()).unwrap();
        let weights = (input().reshape((2, 3, 4, 3)).unwrap().cos().unwrap() * 3.0).unwrap();
        let norm = InstanceNorm2d::default();
        let fused = norm.forward_activated(x.as_tensor(), LEAKY_SLOPE).unwrap();
        let plain = leaky_relu(&norm.forward(x.as_tensor()).unwrap(), LEAKY_SLOPE).unwrap();
        let grad = |y: &Tensor| {
            let loss = (y * &weights).unwrap().sum_all().unwrap();
            let g = loss.backward().unwrap().remove(&x).unwrap();
            g.flatten_all().unwrap().to_vec1::<f64>().unwrap()
        };
        let values = |y: &Tensor| y.flatten_all().unwrap().to_vec1::<f64>().unwrap();
        for (a, b) in values(&fused).iter().zip(values(&plain)) {
            assert!((a - b).abs() < 1e-12, "value {a} vs {b}");
        }
        for (a, b) in grad(&fused).iter().zip(grad(&plain)) {
            assert!((a - b).abs() < 1e-10, "gradient {a} vs {b}");
        }
    }
}

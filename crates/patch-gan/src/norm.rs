//! Normalisation layers: `BatchNorm3d` (train and eval) and `InstanceNorm2d`.

use candle_core::{ModuleT, Tensor};
use candle_nn::{BatchNorm, BatchNormConfig, Module, VarBuilder};

use crate::error::{invalid, Result};

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
#[derive(Debug, Clone)]
pub struct BatchNorm3d(BatchNorm);

impl BatchNorm3d {
    /// The running mean, `(C,)`.
    pub fn running_mean(&self) -> &Tensor {
        self.0.running_mean()
    }

    /// The running (unbiased) variance, `(C,)`.
    pub fn running_var(&self) -> &Tensor {
        self.0.running_var()
    }
}

impl ModuleT for BatchNorm3d {
    fn forward_t(&self, xs: &Tensor, train: bool) -> candle_core::Result<Tensor> {
        if xs.rank() != 5 {
            return Err(invalid(
                "BatchNorm3d input",
                format!("expected (N, C, D, H, W), got {:?}", xs.shape()),
            )
            .into());
        }
        self.0.forward_t(xs, train)
    }
}

/// A [`BatchNorm3d`] over `channels` channels reading or creating its four tensors under `vb`.
pub fn batch_norm3d(channels: usize, vb: VarBuilder) -> Result<BatchNorm3d> {
    if channels == 0 {
        return Err(invalid("BatchNorm3d channels", "must be positive"));
    }
    let config = BatchNormConfig {
        eps: NORM_EPS,
        remove_mean: true,
        affine: true,
        momentum: 0.1,
    };
    Ok(BatchNorm3d(candle_nn::batch_norm(channels, config, vb)?))
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

/// LeakyReLU with slope `negative_slope` for negative inputs: `max(x, 0) + slope min(x, 0)`.
/// The paper uses 0.2 ([`LEAKY_SLOPE`]). Differentiable twice (its derivative is piecewise
/// constant), as the gradient penalty needs.
///
/// ```
/// use candle_core::{Device, Tensor};
/// let y = patch_gan::leaky_relu(&Tensor::new(&[-1f32, 2.], &Device::Cpu)?, 0.2)?;
/// assert_eq!(y.to_vec1::<f32>()?, [-0.2, 2.0]);
/// # Ok::<(), candle_core::Error>(())
/// ```
pub fn leaky_relu(xs: &Tensor, negative_slope: f64) -> candle_core::Result<Tensor> {
    candle_nn::ops::leaky_relu(xs, negative_slope)
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
}

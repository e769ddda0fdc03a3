//! BatchNorm (batch or running statistics) followed by LeakyReLU, as one op each way.
//!
//! Forward: per channel, the mean and variance in f64 (two passes over the channel, which stays
//! in cache), then `y = act(gamma (x - mean) / sqrt(var + eps) + beta)` in one pass. Backward,
//! with `g` the incoming gradient masked by the activation's slope and `xh` the normalised input:
//! `dbeta = sum g`, `dgamma = sum g xh` and, with batch statistics,
//! `dx = gamma / sqrt(var + eps) (g - dbeta / M - xh dgamma / M)` over the `M` values of a channel
//! (with running statistics the last two terms vanish). The loops are `conv_kernels::fused`'s.
//! Second-order gradients through this op are not implemented (candle reports
//! `BackwardNotSupported`): the generators, its users, are differentiated once.

use std::sync::{Arc, Mutex};

use candle_core::{CpuStorage, CustomOp2, CustomOp3, Layout, Shape, Tensor};
use conv_kernels::fused::{self, NormParams};
use conv_kernels::Element;

use super::channels_and_plane;
use crate::storage::{self, Kernel};

/// Which statistics normalise the input.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum NormStats {
    /// The batch's own (training mode).
    Batch,
    /// Given per-channel mean and (biased) variance (evaluation mode).
    Running { mean: Vec<f64>, var: Vec<f64> },
}

/// The per-channel statistics a batch-statistics forward pass measured.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct BatchStats {
    pub mean: Vec<f64>,
    /// Biased (divided by the count).
    pub var: Vec<f64>,
    /// Values per channel.
    pub count: usize,
}

/// `LeakyReLU_slope(gamma (x - mean) / sqrt(var + eps) + beta)` per channel of `xs` `(N, C, ...)`
/// (`slope = 1` is BatchNorm alone), with the batch statistics it used when `stats` is
/// [`NormStats::Batch`]. `gamma` and `beta` are `(C,)`.
pub(crate) fn batch_norm_act(
    xs: &Tensor,
    gamma: &Tensor,
    beta: &Tensor,
    stats: NormStats,
    eps: f64,
    slope: f64,
) -> candle_core::Result<(Tensor, Option<BatchStats>)> {
    let op = BatchNormAct::new(stats, eps, slope);
    let saved = Arc::clone(&op.saved);
    let ys = xs
        .contiguous()?
        .apply_op3(&gamma.contiguous()?, &beta.contiguous()?, op)?;
    let measured = lock(&saved)?.as_ref().and_then(|s| s.batch.clone());
    Ok((ys, measured))
}

/// What the forward pass leaves for the backward pass.
#[derive(Debug, Clone)]
struct Saved {
    params: NormParams,
    batch: Option<BatchStats>,
}

fn lock(
    saved: &Mutex<Option<Saved>>,
) -> candle_core::Result<std::sync::MutexGuard<'_, Option<Saved>>> {
    saved
        .lock()
        .map_err(|_| candle_core::Error::Msg("batch-norm: statistics lock poisoned".into()))
}

struct BatchNormAct {
    stats: NormStats,
    eps: f64,
    slope: f64,
    saved: Arc<Mutex<Option<Saved>>>,
}

impl BatchNormAct {
    fn new(stats: NormStats, eps: f64, slope: f64) -> Self {
        Self {
            stats,
            eps,
            slope,
            saved: Arc::new(Mutex::new(None)),
        }
    }

    /// The gradients of `sum(grad * y)` with respect to the input `x` the forward pass
    /// normalised, gamma and beta, each if `want`ed.
    fn grads(
        &self,
        x: &Tensor,
        grad: &Tensor,
        want: [bool; 3],
    ) -> candle_core::Result<[Option<Tensor>; 3]> {
        let saved = lock(&self.saved)?
            .clone()
            .ok_or_else(|| candle_core::Error::Msg("batch-norm: backward before forward".into()))?;
        let channels = saved.params.channels();
        let backward = BatchNormActGrad {
            saved,
            batch: self.stats == NormStats::Batch,
            slope: self.slope,
            plane: channels_and_plane(x.dims()).1,
        };
        let packed = x.contiguous()?.apply_op2(&grad.contiguous()?, backward)?;
        let len = x.elem_count();
        let [want_x, want_gamma, want_beta] = want;
        Ok([
            want_x
                .then(|| packed.narrow(0, 0, len)?.reshape(x.shape()))
                .transpose()?,
            want_gamma
                .then(|| packed.narrow(0, len, channels))
                .transpose()?,
            want_beta
                .then(|| packed.narrow(0, len + channels, channels))
                .transpose()?,
        ])
    }
}

/// The forward kernel for one input shape.
struct ForwardKernel<'a> {
    op: &'a BatchNormAct,
    channels: usize,
    plane: usize,
    gamma: Vec<f64>,
    beta: Vec<f64>,
}

impl Kernel for ForwardKernel<'_> {
    fn run<T: Element>(&self, x: &[T], _: &[T]) -> candle_core::Result<Vec<T>> {
        let (channels, plane) = (self.channels, self.plane);
        let (mean, var, batch) = match &self.op.stats {
            NormStats::Batch => {
                let stats = fused::channel_stats(x, channels, plane);
                let (mean, var): (Vec<f64>, Vec<f64>) = stats.into_iter().unzip();
                let batch = BatchStats {
                    mean: mean.clone(),
                    var: var.clone(),
                    count: x.len() / channels,
                };
                (mean, var, Some(batch))
            }
            NormStats::Running { mean, var } => (mean.clone(), var.clone(), None),
        };
        let params = NormParams {
            inv_std: var.iter().map(|v| 1.0 / (v + self.op.eps).sqrt()).collect(),
            mean,
            gamma: self.gamma.clone(),
            beta: self.beta.clone(),
        };
        let out = fused::batch_norm_act(x, plane, &params, self.op.slope);
        *lock(&self.op.saved)? = Some(Saved { params, batch });
        Ok(out)
    }
}

impl CustomOp3 for BatchNormAct {
    fn name(&self) -> &'static str {
        "batch-norm-leaky-relu"
    }

    fn cpu_fwd(
        &self,
        s1: &CpuStorage,
        l1: &Layout,
        s2: &CpuStorage,
        l2: &Layout,
        s3: &CpuStorage,
        l3: &Layout,
    ) -> candle_core::Result<(CpuStorage, Shape)> {
        let (channels, plane) = channels_and_plane(l1.dims());
        let gamma = storage::to_f64_vec(self.name(), (s2, l2))?;
        let beta = storage::to_f64_vec(self.name(), (s3, l3))?;
        let running_ok = match &self.stats {
            NormStats::Batch => true,
            NormStats::Running { mean, var } => mean.len() == channels && var.len() == channels,
        };
        if l1.dims().len() < 2
            || plane == 0
            || gamma.len() != channels
            || beta.len() != channels
            || !running_ok
        {
            candle_core::bail!(
                "{}: input {:?} needs (C,) = ({channels},) weight, bias and statistics, got {:?} and {:?}",
                self.name(),
                l1.shape(),
                l2.shape(),
                l3.shape()
            );
        }
        let kernel = ForwardKernel {
            op: self,
            channels,
            plane,
            gamma,
            beta,
        };
        Ok((
            storage::run_unary(self.name(), (s1, l1), &kernel)?,
            l1.shape().clone(),
        ))
    }

    fn bwd(
        &self,
        x: &Tensor,
        gamma: &Tensor,
        beta: &Tensor,
        _y: &Tensor,
        grad: &Tensor,
    ) -> candle_core::Result<(Option<Tensor>, Option<Tensor>, Option<Tensor>)> {
        let want = [x.track_op(), gamma.track_op(), beta.track_op()];
        let [grad_x, grad_gamma, grad_beta] = self.grads(x, grad, want)?;
        Ok((grad_x, grad_gamma, grad_beta))
    }
}

/// `(x, grad_y) -> [grad_x, grad_gamma, grad_beta]` packed in one vector.
struct BatchNormActGrad {
    saved: Saved,
    batch: bool,
    slope: f64,
    /// Values per `(n, c)` plane.
    plane: usize,
}

impl Kernel for BatchNormActGrad {
    fn run<T: Element>(&self, x: &[T], grad: &[T]) -> candle_core::Result<Vec<T>> {
        let stats_and_slope = (self.batch, self.slope);
        Ok(fused::batch_norm_act_backward(
            (x, grad),
            self.plane,
            &self.saved.params,
            stats_and_slope,
        ))
    }
}

impl CustomOp2 for BatchNormActGrad {
    fn name(&self) -> &'static str {
        "batch-norm-leaky-relu-grad"
    }

    fn cpu_fwd(
        &self,
        s1: &CpuStorage,
        l1: &Layout,
        s2: &CpuStorage,
        l2: &Layout,
    ) -> candle_core::Result<(CpuStorage, Shape)> {
        if l1.shape() != l2.shape() {
            candle_core::bail!(
                "{}: input {:?} and gradient {:?} differ",
                self.name(),
                l1.shape(),
                l2.shape()
            );
        }
        let len = l1.shape().elem_count() + 2 * self.saved.params.channels();
        Ok((
            storage::run_binary(self.name(), (s1, l1), (s2, l2), self)?,
            Shape::from(len),
        ))
    }
}

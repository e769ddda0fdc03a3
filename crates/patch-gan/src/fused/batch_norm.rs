//! BatchNorm (batch or running statistics) followed by LeakyReLU, as one op each way.
//!
//! Forward: per channel, the mean and variance in f64 (two passes over the channel, which stays
//! in cache), then `y = act(gamma (x - mean) / sqrt(var + eps) + beta)` in one pass. Backward,
//! with `g` the incoming gradient masked by the activation's slope and `xh` the normalised input:
//! `dbeta = sum g`, `dgamma = sum g xh` and, with batch statistics,
//! `dx = gamma / sqrt(var + eps) (g - dbeta / M - xh dgamma / M)` over the `M` values of a channel
//! (with running statistics the last two terms vanish). Second-order gradients through this op
//! are not implemented (candle reports `BackwardNotSupported`): the generators, its users, are
//! differentiated once.

use std::sync::{Arc, Mutex};

use candle_core::{CpuStorage, CustomOp2, CustomOp3, Layout, Shape, Tensor};
use rayon::prelude::*;

use super::{channels_and_plane, lane_sum, lane_sums, slope_at};
use crate::element::Element;
use crate::output::{extend_par_chunks, unwritten};
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
    mean: Vec<f64>,
    inv_std: Vec<f64>,
    gamma: Vec<f64>,
    beta: Vec<f64>,
    batch: Option<BatchStats>,
}

fn lock(
    saved: &Mutex<Option<Saved>>,
) -> candle_core::Result<std::sync::MutexGuard<'_, Option<Saved>>> {
    saved
        .lock()
        .map_err(|_| candle_core::Error::Msg("batch-norm: statistics lock poisoned".into()))
}

pub(super) struct BatchNormAct {
    stats: NormStats,
    eps: f64,
    slope: f64,
    saved: Arc<Mutex<Option<Saved>>>,
}

impl BatchNormAct {
    pub(super) fn new(stats: NormStats, eps: f64, slope: f64) -> Self {
        Self {
            stats,
            eps,
            slope,
            saved: Arc::new(Mutex::new(None)),
        }
    }

    /// The batch statistics the forward pass measured (with [`NormStats::Batch`]).
    pub(super) fn measured(&self) -> candle_core::Result<Option<BatchStats>> {
        Ok(lock(&self.saved)?.as_ref().and_then(|s| s.batch.clone()))
    }

    /// The gradients of `sum(grad * y)` with respect to the input `x` the forward pass
    /// normalised, gamma and beta, each if `want`ed.
    pub(super) fn grads(
        &self,
        x: &Tensor,
        grad: &Tensor,
        want: [bool; 3],
    ) -> candle_core::Result<[Option<Tensor>; 3]> {
        let saved = lock(&self.saved)?
            .clone()
            .ok_or_else(|| candle_core::Error::Msg("batch-norm: backward before forward".into()))?;
        let channels = saved.mean.len();
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

/// Per-channel `(mean, biased variance)` of `x` `(N, C, plane)`, in f64.
fn channel_stats<T: Element>(x: &[T], channels: usize, plane: usize) -> Vec<(f64, f64)> {
    let batch = x.len() / (channels * plane);
    let count = (batch * plane) as f64;
    (0..channels)
        .into_par_iter()
        .map(|c| {
            let planes = || (0..batch).map(move |n| &x[(n * channels + c) * plane..][..plane]);
            let mean = planes().map(|p| lane_sum(p, |v| v.to_f64())).sum::<f64>() / count;
            let var = planes()
                .map(|p| lane_sum(p, |v| (v.to_f64() - mean).powi(2)))
                .sum::<f64>()
                / count;
            (mean, var)
        })
        .collect()
}

/// The per-channel affine map `x -> x scale + shift` that normalises and applies gamma, beta.
fn affine<T: Element>(s: &Saved, c: usize) -> (T, T) {
    let scale = s.gamma[c] * s.inv_std[c];
    (
        T::from_f64(scale),
        T::from_f64(s.beta[c] - s.mean[c] * scale),
    )
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
                let stats = channel_stats(x, channels, plane);
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
        let saved = Saved {
            inv_std: var.iter().map(|v| 1.0 / (v + self.op.eps).sqrt()).collect(),
            mean,
            gamma: self.gamma.clone(),
            beta: self.beta.clone(),
            batch,
        };
        let slope = T::from_f64(self.op.slope);
        let mut out = unwritten(x.len());
        // SAFETY: every chunk of `out` is written from the chunk of `x` of the same length.
        unsafe {
            extend_par_chunks(&mut out, x.len(), plane, |i, dst| {
                let (scale, shift) = affine::<T>(&saved, i % channels);
                for (d, &v) in dst.iter_mut().zip(&x[i * plane..]) {
                    let pre = v * scale + shift;
                    d.write(pre * slope_at(pre, slope));
                }
            })
        };
        *lock(&self.op.saved)? = Some(saved);
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

impl BatchNormActGrad {
    /// Per channel: `(sum g, sum g xh)` with `g` the gradient through the activation.
    fn sums<T: Element>(
        &self,
        x: &[T],
        grad: &[T],
        channels: usize,
        plane: usize,
    ) -> Vec<(f64, f64)> {
        let batch = x.len() / (channels * plane);
        let slope = T::from_f64(self.slope);
        (0..channels)
            .into_par_iter()
            .map(|c| {
                let (scale, shift) = affine::<T>(&self.saved, c);
                let (mean, inv) = (self.saved.mean[c], self.saved.inv_std[c]);
                let (mut sum_g, mut sum_gx) = (0.0, 0.0);
                for n in 0..batch {
                    let at = (n * channels + c) * plane;
                    let (xs, gs) = (&x[at..][..plane], &grad[at..][..plane]);
                    let masked = |v: T, g: T| (g * slope_at(v * scale + shift, slope)).to_f64();
                    // Two sweeps: the compiler vectorises a single sum, not the pair of them.
                    let [g] = lane_sums(xs, gs, |v, g| [masked(v, g)]);
                    let [gx] = lane_sums(xs, gs, |v, g| [masked(v, g) * (v.to_f64() - mean) * inv]);
                    sum_g += g;
                    sum_gx += gx;
                }
                (sum_g, sum_gx)
            })
            .collect()
    }
}

impl Kernel for BatchNormActGrad {
    fn run<T: Element>(&self, x: &[T], grad: &[T]) -> candle_core::Result<Vec<T>> {
        let (channels, plane) = (self.saved.mean.len(), self.plane);
        let sums = self.sums(x, grad, channels, plane);
        let count = (x.len() / channels) as f64;
        let slope = T::from_f64(self.slope);
        let mut out = unwritten(x.len() + 2 * channels);
        // SAFETY: every chunk of `out` is written from the chunks of `x` and `grad` of the same
        // length.
        unsafe {
            extend_par_chunks(&mut out, x.len(), plane, |i, dst| {
                let (xs, gs) = (&x[i * plane..], &grad[i * plane..]);
                let c = i % channels;
                let (scale, shift) = affine::<T>(&self.saved, c);
                let (mean, inv) = (self.saved.mean[c], self.saved.inv_std[c]);
                let k = self.saved.gamma[c] * inv;
                // dx = k g - k sum_g / M - k xh sum_gx / M, with xh = (x - mean) inv.
                let (sum_g, sum_gx) = if self.batch { sums[c] } else { (0.0, 0.0) };
                let along_x = T::from_f64(-k * sum_gx / count * inv);
                let offset = T::from_f64(-k * sum_g / count);
                let (k, mean) = (T::from_f64(k), T::from_f64(mean));
                for ((d, &v), &g) in dst.iter_mut().zip(xs).zip(gs) {
                    let g = g * slope_at(v * scale + shift, slope);
                    d.write(k * g + along_x * (v - mean) + offset);
                }
            })
        };
        out.extend(sums.iter().map(|&(_, sum_gx)| T::from_f64(sum_gx)));
        out.extend(sums.iter().map(|&(sum_g, _)| T::from_f64(sum_g)));
        Ok(out)
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
        let len = l1.shape().elem_count() + 2 * self.saved.mean.len();
        Ok((
            storage::run_binary(self.name(), (s1, l1), (s2, l2), self)?,
            Shape::from(len),
        ))
    }
}

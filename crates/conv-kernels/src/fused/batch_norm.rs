//! BatchNorm followed by LeakyReLU, forward and backward, per channel of `(N, C, plane)` values.
//!
//! Forward: per channel, the mean and variance in f64 (two passes over the channel, which stays
//! in cache; [`channel_stats`]), then `y = act(gamma (x - mean) / sqrt(var + eps) + beta)` in one
//! pass ([`batch_norm_act`]). Backward ([`batch_norm_act_backward`]), with `g` the incoming
//! gradient masked by the activation's slope and `xh` the normalised input: `dbeta = sum g`,
//! `dgamma = sum g xh` and, with batch statistics,
//! `dx = gamma / sqrt(var + eps) (g - dbeta / M - xh dgamma / M)` over the `M` values of a channel
//! (with running statistics the last two terms vanish).

use rayon::prelude::*;

use super::{lane_sum, lane_sums, slope_at};
use crate::element::Element;
use crate::output::{extend_par_chunks, unwritten};

/// The per-channel values a normalisation runs on, each `(C,)`, in f64.
#[derive(Debug, Clone, PartialEq)]
pub struct NormParams {
    /// The mean subtracted.
    pub mean: Vec<f64>,
    /// `1 / sqrt(var + eps)`.
    pub inv_std: Vec<f64>,
    /// The scale applied after normalising.
    pub gamma: Vec<f64>,
    /// The shift applied after normalising.
    pub beta: Vec<f64>,
}

impl NormParams {
    /// Channels `C`.
    pub fn channels(&self) -> usize {
        self.mean.len()
    }

    /// The per-channel affine map `x -> x scale + shift` that normalises and applies gamma, beta.
    fn affine<T: Element>(&self, c: usize) -> (T, T) {
        let scale = self.gamma[c] * self.inv_std[c];
        (
            T::from_f64(scale),
            T::from_f64(self.beta[c] - self.mean[c] * scale),
        )
    }
}

/// Per-channel `(mean, biased variance)` of `x` `(N, C, plane)` (`C = channels`), in f64: one
/// task per channel, each sum in a fixed order, so the bits do not depend on the thread count.
///
/// ```
/// // (N, C, plane) = (1, 2, 2)
/// let stats = conv_kernels::fused::channel_stats(&[1f32, 3., -2., -2.], 2, 2);
/// assert_eq!(stats, [(2.0, 1.0), (-2.0, 0.0)]);
/// ```
///
/// # Panics
/// If `channels` or `plane` is 0.
pub fn channel_stats<T: Element>(x: &[T], channels: usize, plane: usize) -> Vec<(f64, f64)> {
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

/// `LeakyReLU_slope(gamma (x - mean) inv_std + beta)` per channel of `x` `(N, C, plane)`
/// (`C = params.channels()`; `slope = 1` is BatchNorm alone), one task per `(n, c)` plane.
///
/// # Panics
/// If `plane` is 0, or a parameter has fewer than `C` values while `x` is not empty.
pub fn batch_norm_act<T: Element>(
    x: &[T],
    plane: usize,
    params: &NormParams,
    slope: f64,
) -> Vec<T> {
    let channels = params.channels();
    let slope = T::from_f64(slope);
    let mut out = unwritten(x.len());
    // SAFETY: every chunk of `out` is written from the chunk of `x` of the same length.
    unsafe {
        extend_par_chunks(&mut out, x.len(), plane, |i, dst| {
            let (scale, shift) = params.affine::<T>(i % channels);
            for (d, &v) in dst.iter_mut().zip(&x[i * plane..]) {
                let pre = v * scale + shift;
                d.write(pre * slope_at(pre, slope));
            }
        })
    };
    out
}

/// Per channel: `(sum g, sum g xh)` with `g` the gradient through the activation.
fn grad_sums<T: Element>(
    (x, grad): (&[T], &[T]),
    plane: usize,
    params: &NormParams,
    slope: f64,
) -> Vec<(f64, f64)> {
    let channels = params.channels();
    let batch = x.len() / (channels * plane);
    let slope = T::from_f64(slope);
    (0..channels)
        .into_par_iter()
        .map(|c| {
            let (scale, shift) = params.affine::<T>(c);
            let (mean, inv) = (params.mean[c], params.inv_std[c]);
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

/// The gradients of `sum(grad * y)` for `y = batch_norm_act(x, plane, params, slope)` with
/// respect to `x`, gamma and beta, packed in one vector: `x.len()` values of `dx`, then `C` of
/// `dgamma`, then `C` of `dbeta`. With `batch_stats` the mean and variance are taken as the
/// batch's own (their gradients flow into `dx`), else as constants (running statistics).
///
/// # Panics
/// If `x` and `grad` differ in length, `plane` or `C` is 0, or a parameter has fewer than `C`
/// values.
pub fn batch_norm_act_backward<T: Element>(
    (x, grad): (&[T], &[T]),
    plane: usize,
    params: &NormParams,
    (batch_stats, slope): (bool, f64),
) -> Vec<T> {
    assert_eq!(
        x.len(),
        grad.len(),
        "batch_norm_act_backward: {} inputs and {} gradients",
        x.len(),
        grad.len()
    );
    let channels = params.channels();
    let sums = grad_sums((x, grad), plane, params, slope);
    let count = (x.len() / channels) as f64;
    let slope = T::from_f64(slope);
    let mut out = unwritten(x.len() + 2 * channels);
    // SAFETY: every chunk of `out` is written from the chunks of `x` and `grad` of the same
    // length (they have one length, checked above).
    unsafe {
        extend_par_chunks(&mut out, x.len(), plane, |i, dst| {
            let (xs, gs) = (&x[i * plane..], &grad[i * plane..]);
            let c = i % channels;
            let (scale, shift) = params.affine::<T>(c);
            let (mean, inv) = (params.mean[c], params.inv_std[c]);
            let k = params.gamma[c] * inv;
            // dx = k g - k sum_g / M - k xh sum_gx / M, with xh = (x - mean) inv.
            let (sum_g, sum_gx) = if batch_stats { sums[c] } else { (0.0, 0.0) };
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
    out
}

//! The sum over every axis but the channel axis, as a bias's gradient needs it.

use candle_core::{CpuStorage, CustomOp1, Layout, Shape, Tensor};
use conv_kernels::{fused, Element};

use super::channels_and_plane;
use crate::storage::{self, Kernel};

/// `xs` `(N, C, ...)` summed to `(C,)` (f64 accumulation, one thread per channel): candle's
/// `sum` over several axes walks the tensor on one thread and was a tenth of a critic step.
pub(crate) fn channel_sum(xs: &Tensor) -> candle_core::Result<Tensor> {
    if !xs.device().is_cpu() {
        let summed: Vec<usize> = (0..xs.rank()).filter(|&a| a != 1).collect();
        return xs.sum(summed);
    }
    xs.contiguous()?.apply_op1(ChannelSum)
}

struct ChannelSum;

/// The kernel for one input shape.
struct ChannelSumKernel {
    channels: usize,
    plane: usize,
}

impl Kernel for ChannelSumKernel {
    fn run<T: Element>(&self, x: &[T], _: &[T]) -> candle_core::Result<Vec<T>> {
        Ok(fused::channel_sums(x, self.channels, self.plane))
    }
}

impl CustomOp1 for ChannelSum {
    fn name(&self) -> &'static str {
        "channel-sum"
    }

    fn cpu_fwd(&self, s: &CpuStorage, l: &Layout) -> candle_core::Result<(CpuStorage, Shape)> {
        let (channels, plane) = channels_and_plane(l.dims());
        if l.dims().len() < 2 || channels == 0 || plane == 0 {
            candle_core::bail!(
                "{}: expected a non-empty (N, C, ...) input, got {:?}",
                self.name(),
                l.shape()
            );
        }
        let kernel = ChannelSumKernel { channels, plane };
        Ok((
            storage::run_unary(self.name(), (s, l), &kernel)?,
            Shape::from(channels),
        ))
    }

    /// Every summed value gets the gradient of its channel.
    fn bwd(&self, x: &Tensor, _res: &Tensor, grad: &Tensor) -> candle_core::Result<Option<Tensor>> {
        let mut shape = vec![1; x.rank()];
        shape[1] = x.dim(1)?;
        Ok(Some(
            grad.reshape(shape)?.broadcast_as(x.shape())?.contiguous()?,
        ))
    }
}

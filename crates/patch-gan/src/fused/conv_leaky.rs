//! A grid convolution followed by a per-channel bias and LeakyReLU, as one op: the critics'
//! hidden layers.
//!
//! The same kernels as `conv3d` then `bias_leaky_relu`, with the same bits; what goes is the
//! graph node between them, whose gradient candle's backward pass would add into a fresh zero
//! tensor of the layer's size. The backward pass is made of differentiable ops (the mask of
//! LeakyReLU comes from the output's sign), so gradients of any order remain available.

use candle_core::{CpuStorage, CustomOp2, CustomOp3, Layout, Shape, Tensor};

use super::channel_sum::channel_sum;
use super::leaky::{leaky_grad, BiasLeaky};
use crate::conv::op::{grid_conv_grads, grid_conv_storage};
use crate::conv::ConvConfig;

/// `LeakyReLU_slope(conv3d(xs, kernel, cfg) + bias)`, `bias` `(C_out,)`, on the CPU.
pub(crate) fn conv_bias_leaky(
    xs: &Tensor,
    kernel: &Tensor,
    cfg: ConvConfig,
    bias: &Tensor,
    slope: f64,
) -> candle_core::Result<Tensor> {
    xs.contiguous()?.apply_op3(
        &kernel.contiguous()?,
        &bias.contiguous()?,
        ConvBiasLeaky { cfg, slope },
    )
}

/// The op: `(xs, kernel, bias) -> ys`.
struct ConvBiasLeaky {
    cfg: ConvConfig,
    slope: f64,
}

impl CustomOp3 for ConvBiasLeaky {
    fn name(&self) -> &'static str {
        "conv-bias-leaky-relu"
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
        let (z, z_shape) = grid_conv_storage(self.cfg, (s1, l1), (s2, l2))?;
        BiasLeaky(self.slope).cpu_fwd(&z, &Layout::contiguous(&z_shape), s3, l3)
    }

    fn bwd(
        &self,
        xs: &Tensor,
        kernel: &Tensor,
        bias: &Tensor,
        ys: &Tensor,
        grad: &Tensor,
    ) -> candle_core::Result<(Option<Tensor>, Option<Tensor>, Option<Tensor>)> {
        let pre = leaky_grad(grad, ys, self.slope)?;
        let grad_bias = bias.track_op().then(|| channel_sum(&pre)).transpose()?;
        let (grad_xs, grad_kernel) = grid_conv_grads(xs, kernel, self.cfg, &pre)?;
        Ok((grad_xs, grad_kernel, grad_bias))
    }
}

#[cfg(test)]
mod tests {
    use candle_core::Var;

    use super::*;
    use crate::conv::op::conv3d;
    use crate::fused::bias_leaky_relu;
    use crate::fused::tests::{assert_same_values_and_gradients, random};

    /// The fused op against `conv3d` then `bias_leaky_relu`: the same outputs and gradients,
    /// bit for bit, on the im2col kernel (3 input channels) and the Winograd one (16).
    #[test]
    fn fused_equals_convolution_then_bias_leaky_relu() {
        for (c_in, seed) in [(3, 1), (16, 2)] {
            let x = Var::from_tensor(&random(&[2, c_in, 1, 9, 10], seed)).unwrap();
            let k = Var::from_tensor(&random(&[5, c_in, 1, 3, 3], seed + 10)).unwrap();
            let bias = Var::from_tensor(&random(&[5], seed + 20)).unwrap();
            let weights = random(&[2, 5, 1, 7, 8], seed + 30);
            let cfg = ConvConfig::default();
            let fused = conv_bias_leaky(&x, &k, cfg, &bias, 0.2).unwrap();
            let plain = bias_leaky_relu(&conv3d(&x, &k, cfg).unwrap(), &bias, 0.2).unwrap();
            let vars = [("x", &x), ("kernel", &k), ("bias", &bias)];
            let case = format!("{c_in} channels");
            assert_same_values_and_gradients((&fused, &plain), &weights, &vars, &case);
        }
    }
}

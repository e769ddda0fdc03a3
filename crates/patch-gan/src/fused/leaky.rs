//! LeakyReLU and bias + LeakyReLU as custom ops whose gradients are themselves differentiable, as
//! the WGAN-GP penalty (a gradient of the critic's input gradient) needs.

use candle_core::{CpuStorage, CustomOp1, CustomOp2, Layout, Shape, Tensor};
use conv_kernels::{fused, Element};

use super::channel_sum::channel_sum;
use super::channels_and_plane;
use crate::storage::{self, Kernel};

/// `LeakyReLU(x) = x` for `x > 0`, else `negative_slope x`, element-wise; differentiable to any
/// order (the gradient is the incoming gradient times the slope of the branch the output lies on,
/// whose own derivative with respect to `x` is zero almost everywhere).
///
/// On the CPU (f32, f64) this is one threaded pass; on other devices candle ops.
///
/// ```
/// use candle_core::{Device, Tensor};
/// let x = Tensor::new(&[-2f32, 0., 3.], &Device::Cpu)?;
/// let y = patch_gan::leaky_relu(&x, 0.2)?;
/// assert_eq!(y.to_vec1::<f32>()?, [-0.4, 0., 3.]);
/// # Ok::<(), candle_core::Error>(())
/// ```
pub fn leaky_relu(xs: &Tensor, negative_slope: f64) -> candle_core::Result<Tensor> {
    if !xs.device().is_cpu() {
        return leaky_relu_by_ops(xs, negative_slope);
    }
    xs.contiguous()?.apply_op1(Leaky(negative_slope))
}

/// [`leaky_relu`] from candle ops, for devices without the CPU kernel: `x * slope(x)`, the
/// slope (1 or `negative_slope`) a constant of the graph, as it is almost everywhere. Two
/// tensors of the input's size are kept for the backward pass (candle keeps every intermediate)
/// where candle-nn's `max(x, 0) + slope * min(x, 0)` keeps five.
pub(crate) fn leaky_relu_by_ops(xs: &Tensor, negative_slope: f64) -> candle_core::Result<Tensor> {
    let slope = xs
        .ge(0.0)?
        .to_dtype(xs.dtype())?
        .affine(1.0 - negative_slope, negative_slope)?;
    xs * slope
}

/// `LeakyReLU(x + bias)` with `bias` `(C,)` added along axis 1 of `xs` `(N, C, ...)`: a
/// convolution's bias and activation in one pass, differentiable to any order like
/// [`leaky_relu`].
///
/// ```
/// use candle_core::{Device, Tensor};
/// let x = Tensor::new(&[[[-1f32, 1.], [0., 2.]]], &Device::Cpu)?; // (1, 2, 2)
/// let b = Tensor::new(&[0.5f32, -1.], &Device::Cpu)?;
/// let y = patch_gan::bias_leaky_relu(&x, &b, 0.2)?;
/// assert_eq!(y.to_vec3::<f32>()?, [[[-0.1, 1.5], [-0.2, 1.]]]);
/// # Ok::<(), candle_core::Error>(())
/// ```
pub fn bias_leaky_relu(
    xs: &Tensor,
    bias: &Tensor,
    negative_slope: f64,
) -> candle_core::Result<Tensor> {
    let (channels, _) = channels_and_plane(xs.dims());
    if xs.rank() < 2 || bias.dims() != [channels] {
        candle_core::bail!(
            "bias_leaky_relu: expected an (N, C, ...) input and a (C,) bias, got {:?} and {:?}",
            xs.shape(),
            bias.shape()
        );
    }
    if !xs.device().is_cpu() {
        let mut shape = vec![1; xs.rank()];
        shape[1] = channels;
        return candle_nn::ops::leaky_relu(
            &xs.broadcast_add(&bias.reshape(shape)?)?,
            negative_slope,
        );
    }
    xs.contiguous()?
        .apply_op2(&bias.contiguous()?, BiasLeaky(negative_slope))
}

/// `xs + bias` with `bias` `(C,)` along axis 1 of `xs` `(N, C, ...)`: [`bias_leaky_relu`] with
/// slope 1, the identity. candle's `broadcast_add` is the same sum, but its backward reduces the
/// gradient to the bias with `sum_keepdim` over every other axis, one thread striding across the
/// tensor (18% of the main thread's samples in the upsampler's training scale); here the bias's
/// gradient is the per-channel parallel sum and the input's is the incoming gradient as it is.
pub(crate) fn bias_add(xs: &Tensor, bias: &Tensor) -> candle_core::Result<Tensor> {
    bias_leaky_relu(xs, bias, 1.0)
}

/// `grad` times the slope of the LeakyReLU branch `output` lies on: positive outputs come from
/// positive inputs (the slope is positive), so the output tells the branch. The output enters
/// detached: the slope does not change with it (almost everywhere), and candle's backward pass
/// insists on a gradient for every tracked argument.
pub(crate) fn leaky_grad(
    grad: &Tensor,
    output: &Tensor,
    slope: f64,
) -> candle_core::Result<Tensor> {
    if slope == 1.0 {
        // The identity ([`bias_add`]): both branches pass the gradient as it is, so no pass over it.
        return Ok(grad.clone());
    }
    grad.contiguous()?
        .apply_op2(&output.detach().contiguous()?, LeakyGrad(slope))
}

struct Leaky(f64);

impl Kernel for Leaky {
    fn run<T: Element>(&self, x: &[T], _: &[T]) -> candle_core::Result<Vec<T>> {
        Ok(fused::leaky_relu(x, self.0))
    }
}

impl CustomOp1 for Leaky {
    fn name(&self) -> &'static str {
        "leaky-relu"
    }

    fn cpu_fwd(&self, s: &CpuStorage, l: &Layout) -> candle_core::Result<(CpuStorage, Shape)> {
        Ok((
            storage::run_unary(self.name(), (s, l), self)?,
            l.shape().clone(),
        ))
    }

    fn bwd(&self, _x: &Tensor, y: &Tensor, grad: &Tensor) -> candle_core::Result<Option<Tensor>> {
        leaky_grad(grad, y, self.0).map(Some)
    }
}

/// `(grad, output) -> grad * slope(output)`.
struct LeakyGrad(f64);

impl Kernel for LeakyGrad {
    fn run<T: Element>(&self, grad: &[T], y: &[T]) -> candle_core::Result<Vec<T>> {
        if grad.len() != y.len() {
            candle_core::bail!(
                "leaky-relu-grad: {} gradients for {} outputs",
                grad.len(),
                y.len()
            );
        }
        Ok(fused::leaky_relu_grad(grad, y, self.0))
    }
}

impl CustomOp2 for LeakyGrad {
    fn name(&self) -> &'static str {
        "leaky-relu-grad"
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
                "{}: gradient {:?} and output {:?} differ",
                self.name(),
                l1.shape(),
                l2.shape()
            );
        }
        Ok((
            storage::run_binary(self.name(), (s1, l1), (s2, l2), self)?,
            l1.shape().clone(),
        ))
    }

    /// Linear in the gradient, piecewise constant in the output.
    fn bwd(
        &self,
        _grad: &Tensor,
        y: &Tensor,
        _res: &Tensor,
        grad2: &Tensor,
    ) -> candle_core::Result<(Option<Tensor>, Option<Tensor>)> {
        Ok((Some(leaky_grad(grad2, y, self.0)?), None))
    }
}

/// `(x, bias) -> LeakyReLU(x + bias along axis 1)`.
pub(super) struct BiasLeaky(pub(super) f64);

/// The kernel of [`BiasLeaky`] for one input shape (its bias has one value per channel).
struct BiasLeakyKernel {
    slope: f64,
    plane: usize,
}

impl Kernel for BiasLeakyKernel {
    fn run<T: Element>(&self, x: &[T], bias: &[T]) -> candle_core::Result<Vec<T>> {
        Ok(fused::bias_leaky_relu(x, bias, self.plane, self.slope))
    }
}

impl CustomOp2 for BiasLeaky {
    fn name(&self) -> &'static str {
        "bias-leaky-relu"
    }

    fn cpu_fwd(
        &self,
        s1: &CpuStorage,
        l1: &Layout,
        s2: &CpuStorage,
        l2: &Layout,
    ) -> candle_core::Result<(CpuStorage, Shape)> {
        let (channels, plane) = channels_and_plane(l1.dims());
        if l2.dims() != [channels] || plane == 0 {
            candle_core::bail!(
                "{}: input {:?} and bias {:?} do not match",
                self.name(),
                l1.shape(),
                l2.shape()
            );
        }
        let kernel = BiasLeakyKernel {
            slope: self.0,
            plane,
        };
        Ok((
            storage::run_binary(self.name(), (s1, l1), (s2, l2), &kernel)?,
            l1.shape().clone(),
        ))
    }

    fn bwd(
        &self,
        x: &Tensor,
        bias: &Tensor,
        y: &Tensor,
        grad: &Tensor,
    ) -> candle_core::Result<(Option<Tensor>, Option<Tensor>)> {
        let pre = leaky_grad(grad, y, self.0)?;
        let grad_bias = bias.track_op().then(|| channel_sum(&pre)).transpose()?;
        let grad_x = x.track_op().then_some(pre);
        Ok((grad_x, grad_bias))
    }
}

//! The candle custom ops around the CPU kernels, and the public functional `conv3d`.

use candle_core::backend::BackendStorage;
use candle_core::{CpuStorage, CustomOp2, Layout, Shape, Tensor};

use super::cpu::{self, Geometry};
use super::Conv3dConfig;
use crate::error::{invalid, Result};

/// 3D cross-correlation of `xs` `(N, C_in, D, H, W)` with `kernel` `(C_out, C_in, k, k, k)`, as
/// PyTorch's `torch.nn.functional.conv3d(xs, kernel, stride=cfg.stride, padding=cfg.padding)`.
///
/// The output is `(N, C_out, D_out, H_out, W_out)` with `D_out = (D + 2 padding - k) / stride + 1`
/// (and likewise for H, W). It is differentiable with respect to both arguments (first order);
/// f32 and f64 run on the CPU.
///
/// ```
/// use candle_core::{Device, Tensor};
/// use patch_gan::{functional, Conv3dConfig};
/// let x = Tensor::ones((1, 2, 4, 4, 4), candle_core::DType::F32, &Device::Cpu)?;
/// let k = Tensor::ones((3, 2, 3, 3, 3), candle_core::DType::F32, &Device::Cpu)?;
/// let y = functional::conv3d(&x, &k, Conv3dConfig { padding: 1, stride: 1 })?;
/// assert_eq!(y.dims(), &[1, 3, 4, 4, 4]);
/// // The centre voxel sees 2 channels x 27 taps of ones.
/// assert_eq!(y.get(0)?.get(0)?.get(1)?.get(1)?.get(1)?.to_scalar::<f32>()?, 54.0);
/// # Ok::<(), patch_gan::Error>(())
/// ```
pub fn conv3d(xs: &Tensor, kernel: &Tensor, cfg: Conv3dConfig) -> Result<Tensor> {
    let g = geometry(xs.shape(), kernel.shape(), cfg)?;
    if !xs.device().is_cpu() {
        return super::slices::conv3d_by_slices(xs, kernel, &g);
    }
    let xs = xs.contiguous()?;
    let kernel = kernel.contiguous()?;
    Ok(xs.apply_op2(&kernel, Conv3dOp(cfg))?)
}

/// [`conv3d`] built from candle's conv2d over depth slices (what non-CPU devices run); public
/// so tests and benchmarks can compare it with the CPU kernel.
///
/// ```
/// use candle_core::{Device, Tensor};
/// use patch_gan::{functional, Conv3dConfig};
/// let x = Tensor::rand(-1f32, 1., (1, 2, 5, 4, 3), &Device::Cpu)?;
/// let k = Tensor::rand(-1f32, 1., (3, 2, 3, 3, 3), &Device::Cpu)?;
/// let cfg = Conv3dConfig { padding: 1, stride: 1 };
/// let a = functional::conv3d(&x, &k, cfg)?;
/// let b = functional::conv3d_by_slices(&x, &k, cfg)?;
/// let diff = (a - b)?.abs()?.flatten_all()?.max(0)?.to_scalar::<f32>()?;
/// assert!(diff < 1e-5);
/// # Ok::<(), patch_gan::Error>(())
/// ```
pub fn conv3d_by_slices(xs: &Tensor, kernel: &Tensor, cfg: Conv3dConfig) -> Result<Tensor> {
    let g = geometry(xs.shape(), kernel.shape(), cfg)?;
    super::slices::conv3d_by_slices(xs, kernel, &g)
}

/// Checks the shapes and returns the geometry of `conv3d(xs, kernel)`.
fn geometry(xs: &Shape, kernel: &Shape, cfg: Conv3dConfig) -> Result<Geometry> {
    let &[batch, c_in, d, h, w] = xs.dims() else {
        return Err(invalid(
            "input",
            format!("expected (N, C, D, H, W), got {xs:?}"),
        ));
    };
    let &[c_out, kc_in, kd, kh, kw] = kernel.dims() else {
        return Err(invalid(
            "kernel",
            format!("expected (C_out, C_in, k, k, k), got {kernel:?}"),
        ));
    };
    if kd != kh || kd != kw || kd == 0 {
        return Err(invalid(
            "kernel",
            format!("only non-empty cubic kernels are supported, got {kernel:?}"),
        ));
    }
    if kc_in != c_in {
        return Err(invalid(
            "kernel",
            format!("kernel {kernel:?} expects {kc_in} input channels, input {xs:?} has {c_in}"),
        ));
    }
    if cfg.stride == 0 {
        return Err(invalid("stride", "must be at least 1"));
    }
    if [d, h, w].iter().any(|&n| n + 2 * cfg.padding < kd) {
        return Err(invalid(
            "input",
            format!(
                "input {xs:?} with padding {} is smaller than the kernel {kd}",
                cfg.padding
            ),
        ));
    }
    Ok(Geometry {
        batch,
        c_in,
        c_out,
        input: [d, h, w],
        kernel: kd,
        padding: cfg.padding,
        stride: cfg.stride,
    })
}

/// The contiguous data of a storage, or an error naming the op.
fn data<'a, T>(values: &'a [T], layout: &Layout, op: &'static str) -> candle_core::Result<&'a [T]> {
    match layout.contiguous_offsets() {
        Some((start, end)) => Ok(&values[start..end]),
        None => candle_core::bail!("{op}: inputs have to be contiguous"),
    }
}

/// Runs a two-input kernel on f32 or f64 storages of the same dtype.
fn run<F32, F64>(
    name: &'static str,
    (s1, l1): (&CpuStorage, &Layout),
    (s2, l2): (&CpuStorage, &Layout),
    f32_kernel: F32,
    f64_kernel: F64,
) -> candle_core::Result<CpuStorage>
where
    F32: FnOnce(&[f32], &[f32]) -> Vec<f32>,
    F64: FnOnce(&[f64], &[f64]) -> Vec<f64>,
{
    match (s1, s2) {
        (CpuStorage::F32(a), CpuStorage::F32(b)) => Ok(CpuStorage::F32(f32_kernel(
            data(a, l1, name)?,
            data(b, l2, name)?,
        ))),
        (CpuStorage::F64(a), CpuStorage::F64(b)) => Ok(CpuStorage::F64(f64_kernel(
            data(a, l1, name)?,
            data(b, l2, name)?,
        ))),
        (CpuStorage::F32(_) | CpuStorage::F64(_), other) => {
            Err(candle_core::Error::DTypeMismatchBinaryOp {
                lhs: s1.dtype(),
                rhs: other.dtype(),
                op: name,
            })
        }
        _ => Err(candle_core::Error::UnsupportedDTypeForOp(s1.dtype(), name)),
    }
}

fn checked(shape_a: &Shape, shape_b: &Shape, cfg: Conv3dConfig) -> candle_core::Result<Geometry> {
    geometry(shape_a, shape_b, cfg).map_err(candle_core::Error::from)
}

/// Forward op: `(x, kernel) -> y`.
struct Conv3dOp(Conv3dConfig);

impl CustomOp2 for Conv3dOp {
    fn name(&self) -> &'static str {
        "conv3d"
    }

    fn cpu_fwd(
        &self,
        s1: &CpuStorage,
        l1: &Layout,
        s2: &CpuStorage,
        l2: &Layout,
    ) -> candle_core::Result<(CpuStorage, Shape)> {
        let g = checked(l1.shape(), l2.shape(), self.0)?;
        let [d, h, w] = g.output();
        let out = run(
            self.name(),
            (s1, l1),
            (s2, l2),
            |x, k| cpu::forward(x, k, &g),
            |x, k| cpu::forward(x, k, &g),
        )?;
        Ok((out, Shape::from((g.batch, g.c_out, d, h, w))))
    }

    fn bwd(
        &self,
        xs: &Tensor,
        kernel: &Tensor,
        _res: &Tensor,
        grad: &Tensor,
    ) -> candle_core::Result<(Option<Tensor>, Option<Tensor>)> {
        let grad = grad.contiguous()?;
        let grad_xs = grad.apply_op2_no_bwd(kernel, &GradInputOp(self.0, xs.shape().clone()))?;
        let grad_kernel =
            xs.apply_op2_no_bwd(&grad, &GradKernelOp(self.0, kernel.shape().clone()))?;
        Ok((Some(grad_xs), Some(grad_kernel)))
    }
}

/// Input gradient: `(grad_out, kernel) -> grad_x` for an input of the stored shape.
struct GradInputOp(Conv3dConfig, Shape);

impl CustomOp2 for GradInputOp {
    fn name(&self) -> &'static str {
        "conv3d-grad-input"
    }

    fn cpu_fwd(
        &self,
        s1: &CpuStorage,
        l1: &Layout,
        s2: &CpuStorage,
        l2: &Layout,
    ) -> candle_core::Result<(CpuStorage, Shape)> {
        let g = checked(&self.1, l2.shape(), self.0)?;
        let out = run(
            self.name(),
            (s1, l1),
            (s2, l2),
            |go, k| cpu::grad_input(go, k, &g),
            |go, k| cpu::grad_input(go, k, &g),
        )?;
        Ok((out, self.1.clone()))
    }
}

/// Kernel gradient: `(x, grad_out) -> grad_kernel` for a kernel of the stored shape.
struct GradKernelOp(Conv3dConfig, Shape);

impl CustomOp2 for GradKernelOp {
    fn name(&self) -> &'static str {
        "conv3d-grad-kernel"
    }

    fn cpu_fwd(
        &self,
        s1: &CpuStorage,
        l1: &Layout,
        s2: &CpuStorage,
        l2: &Layout,
    ) -> candle_core::Result<(CpuStorage, Shape)> {
        let g = checked(l1.shape(), &self.1, self.0)?;
        let out = run(
            self.name(),
            (s1, l1),
            (s2, l2),
            |x, go| cpu::grad_weight(x, go, &g),
            |x, go| cpu::grad_weight(x, go, &g),
        )?;
        Ok((out, self.1.clone()))
    }
}

//! The candle custom ops around the CPU kernels, and the public functional `conv3d` / `conv2d`.
//!
//! The three ops (forward, input gradient, kernel gradient) are the three partial derivatives of
//! one trilinear form `B(x, w, g) = <conv(x, w), g>`, so the backward of each is made of the other
//! two. Their backward passes build tracked tensors, which makes gradients of any order available
//! (the WGAN-GP penalty differentiates the critic's input gradient with respect to its weights).

use std::sync::Arc;

use candle_core::{CpuStorage, CustomOp2, Layout, Shape, Tensor};
use conv_kernels::{im2col, winograd, Element, Geometry};

use super::active::{self, ActiveGeometry};
use super::ConvConfig;
use crate::active::ActiveSites;
use crate::error::{invalid, Result};
use crate::storage;

/// 3D cross-correlation of `xs` `(N, C_in, D, H, W)` with `kernel` `(C_out, C_in, kd, kh, kw)`,
/// as PyTorch's `torch.nn.functional.conv3d(xs, kernel, stride=cfg.stride, padding=cfg.padding)`.
///
/// The output is `(N, C_out, D_out, H_out, W_out)` with `D_out = (D + 2 padding - kd) / stride + 1`
/// (and likewise for H, W). It is differentiable with respect to both arguments, to any order;
/// f32 and f64 run on the CPU kernel, other devices on candle's conv2d over depth slices.
///
/// ```
/// use candle_core::{Device, Tensor};
/// use patch_gan::{functional, ConvConfig};
/// let x = Tensor::ones((1, 2, 4, 4, 4), candle_core::DType::F32, &Device::Cpu)?;
/// let k = Tensor::ones((3, 2, 3, 3, 3), candle_core::DType::F32, &Device::Cpu)?;
/// let y = functional::conv3d(&x, &k, ConvConfig { padding: 1, stride: 1 })?;
/// assert_eq!(y.dims(), &[1, 3, 4, 4, 4]);
/// // The centre voxel sees 2 channels x 27 taps of ones.
/// assert_eq!(y.get(0)?.get(0)?.get(1)?.get(1)?.get(1)?.to_scalar::<f32>()?, 54.0);
/// # Ok::<(), patch_gan::Error>(())
/// ```
pub fn conv3d(xs: &Tensor, kernel: &Tensor, cfg: ConvConfig) -> Result<Tensor> {
    let spec = Spec::uniform(cfg);
    let g = geometry(xs.shape(), kernel.shape(), spec)?;
    if !xs.device().is_cpu() {
        return super::slices::conv3d_by_slices(xs, kernel, &g);
    }
    Ok(apply(xs, kernel, ConvOp(Domain::Grid(spec)))?)
}

/// 2D cross-correlation of `xs` `(N, C_in, H, W)` with `kernel` `(C_out, C_in, kh, kw)`, as
/// PyTorch's `torch.nn.functional.conv2d(xs, kernel, stride=cfg.stride, padding=cfg.padding)`.
///
/// On the CPU this runs the same chunked im2col + `gemm` kernel as [`conv3d`] (a 2D convolution
/// is a 3D one of depth 1) and is differentiable to any order; on other devices it is candle's
/// own `conv2d`. candle 0.11's CPU conv2d is a direct loop whose backward pass is a slow
/// transposed convolution: this op is several times faster for the critics' small kernels (see
/// `cargo bench -p patch-gan`).
///
/// ```
/// use candle_core::{Device, Tensor};
/// use patch_gan::{functional, ConvConfig};
/// let x = Tensor::rand(-1f32, 1., (2, 3, 9, 7), &Device::Cpu)?;
/// let k = Tensor::rand(-1f32, 1., (4, 3, 3, 3), &Device::Cpu)?;
/// let ours = functional::conv2d(&x, &k, ConvConfig::default().with_padding(1))?;
/// let candle = x.conv2d(&k, 1, 1, 1, 1)?;
/// assert_eq!(ours.dims(), &[2, 4, 9, 7]);
/// let diff = (ours - candle)?.abs()?.flatten_all()?.max(0)?.to_scalar::<f32>()?;
/// assert!(diff < 1e-5);
/// # Ok::<(), patch_gan::Error>(())
/// ```
pub fn conv2d(xs: &Tensor, kernel: &Tensor, cfg: ConvConfig) -> Result<Tensor> {
    let (n, c_in, h, w) = xs.dims4().map_err(|_| {
        invalid(
            "input",
            format!("expected (N, C, H, W), got {:?}", xs.shape()),
        )
    })?;
    let (c_out, kc_in, kh, kw) = kernel.dims4().map_err(|_| {
        invalid(
            "kernel",
            format!("expected (C_out, C_in, kh, kw), got {:?}", kernel.shape()),
        )
    })?;
    if !xs.device().is_cpu() {
        return Ok(xs.conv2d(kernel, cfg.padding, cfg.stride, 1, 1)?);
    }
    let spec = Spec {
        padding: [0, cfg.padding, cfg.padding],
        stride: cfg.stride,
    };
    let xs = xs.reshape((n, c_in, 1, h, w))?;
    let kernel = kernel.reshape((c_out, kc_in, 1, kh, kw))?;
    let g = geometry(xs.shape(), kernel.shape(), spec)?;
    let [_, h_out, w_out] = g.output();
    Ok(apply(&xs, &kernel, ConvOp(Domain::Grid(spec)))?.reshape((n, c_out, h_out, w_out))?)
}

/// [`conv3d`] built from candle's conv2d over depth slices (what non-CPU devices run); public
/// so tests and benchmarks can compare it with the CPU kernel.
///
/// ```
/// use candle_core::{Device, Tensor};
/// use patch_gan::{functional, ConvConfig};
/// let x = Tensor::rand(-1f32, 1., (1, 2, 5, 4, 3), &Device::Cpu)?;
/// let k = Tensor::rand(-1f32, 1., (3, 2, 3, 3, 3), &Device::Cpu)?;
/// let cfg = ConvConfig { padding: 1, stride: 1 };
/// let a = functional::conv3d(&x, &k, cfg)?;
/// let b = functional::conv3d_by_slices(&x, &k, cfg)?;
/// let diff = (a - b)?.abs()?.flatten_all()?.max(0)?.to_scalar::<f32>()?;
/// assert!(diff < 1e-5);
/// # Ok::<(), patch_gan::Error>(())
/// ```
pub fn conv3d_by_slices(xs: &Tensor, kernel: &Tensor, cfg: ConvConfig) -> Result<Tensor> {
    let g = geometry(xs.shape(), kernel.shape(), Spec::uniform(cfg))?;
    super::slices::conv3d_by_slices(xs, kernel, &g)
}

/// The submanifold 3D convolution of `features` `(1, C_in, M, 1, 1)` on the `M` active `sites`
/// with `kernel` `(C_out, C_in, k, k, k)` (`k` the sites' kernel, padding `k / 2`): outputs
/// `(1, C_out, M, 1, 1)` at the active sites only, reading inactive voxels (and the box's outside)
/// as zero. Equal to the dense [`conv3d`] of the features scattered into their volumes, gathered
/// back at the sites (see [`ActiveSites`]); differentiable with respect to both arguments, to any
/// order. CPU only.
///
/// ```
/// use std::sync::Arc;
/// use candle_core::{Device, Tensor};
/// use patch_gan::{active, functional, ActiveSites, ConvConfig};
/// let dev = Device::Cpu;
/// let x = Tensor::rand(-1f32, 1., (1, 2, 4, 4, 4), &dev)?;
/// let k = Tensor::rand(-1f32, 1., (3, 2, 3, 3, 3), &dev)?;
/// // Every other voxel active.
/// let mask: Vec<f32> = (0..64).map(|i| (i % 2) as f32).collect();
/// let mask = Tensor::from_vec(mask, (1, 1, 4, 4, 4), &dev)?;
/// let sites = Arc::new(ActiveSites::from_mask(&mask, 3)?);
/// let sparse = functional::conv3d_active(&active::gather(&x, &sites)?, &k, &sites)?;
/// let dense = functional::conv3d(&x.broadcast_mul(&mask)?, &k, ConvConfig::default().with_padding(1))?;
/// let diff = (sparse - active::gather(&dense, &sites)?)?.abs()?.flatten_all()?.max(0)?;
/// assert!(diff.to_scalar::<f32>()? < 1e-5);
/// # Ok::<(), patch_gan::Error>(())
/// ```
pub fn conv3d_active(
    features: &Tensor,
    kernel: &Tensor,
    sites: &Arc<ActiveSites>,
) -> Result<Tensor> {
    if !features.device().is_cpu() {
        return Err(invalid("conv3d_active", "runs on the CPU only"));
    }
    let domain = Domain::Active(Arc::clone(sites));
    domain.plan(features.shape(), kernel.shape())?;
    Ok(apply(features, kernel, ConvOp(domain))?)
}

/// Where a convolution is evaluated: on the whole grid with padding and stride, or on the
/// active sites of a set (submanifold).
#[derive(Debug, Clone)]
pub(crate) enum Domain {
    Grid(Spec),
    Active(Arc<ActiveSites>),
}

/// A convolution's geometry, checked against its arguments' shapes.
#[derive(Debug, Clone)]
pub(crate) enum Plan {
    Grid(Geometry),
    Active(ActiveGeometry),
}

impl Domain {
    /// The whole grid, with `cfg`'s padding and stride.
    pub(crate) fn grid(cfg: ConvConfig) -> Self {
        Domain::Grid(Spec::uniform(cfg))
    }

    /// The active `sites`.
    pub(crate) fn active(sites: &Arc<ActiveSites>) -> Self {
        Domain::Active(Arc::clone(sites))
    }

    /// The geometry of `conv(xs, kernel)` in this domain, or an error naming the bad shape.
    pub(crate) fn plan(&self, xs: &Shape, kernel: &Shape) -> Result<Plan> {
        match self {
            Domain::Grid(spec) => Ok(Plan::Grid(geometry(xs, kernel, *spec)?)),
            Domain::Active(sites) => Ok(Plan::Active(active_geometry(xs, kernel, sites)?)),
        }
    }

    fn checked(&self, xs: &Shape, kernel: &Shape) -> candle_core::Result<Plan> {
        self.plan(xs, kernel).map_err(candle_core::Error::from)
    }
}

impl Plan {
    /// `conv(x, w)` on plain slices.
    pub(crate) fn forward<T: Element>(&self, x: &[T], w: &[T]) -> Vec<T> {
        match self {
            Plan::Grid(g) => grid::forward(x, w, g),
            Plan::Active(g) => im2col::forward(x, w, g),
        }
    }

    /// The input gradient of `sum(grad_out * conv(x, w))`.
    pub(crate) fn grad_input<T: Element>(&self, grad_out: &[T], w: &[T]) -> Vec<T> {
        match self {
            Plan::Grid(g) => grid::grad_input(grad_out, w, g),
            Plan::Active(g) => active::grad_input(grad_out, w, g),
        }
    }

    /// The kernel gradient of `sum(grad_out * conv(x, w))`.
    pub(crate) fn grad_weight<T: Element>(&self, x: &[T], grad_out: &[T]) -> Vec<T> {
        match self {
            Plan::Grid(g) => grid::grad_weight(x, grad_out, g),
            Plan::Active(g) => im2col::grad_weight(x, grad_out, g),
        }
    }

    pub(crate) fn output_shape(&self) -> Shape {
        match self {
            Plan::Grid(g) => {
                let [d, h, w] = g.output();
                Shape::from((g.batch, g.c_out, d, h, w))
            }
            Plan::Active(g) => Shape::from((1, g.c_out, g.sites.len(), 1, 1)),
        }
    }
}

/// Checks the shapes of a convolution on active sites.
fn active_geometry(xs: &Shape, kernel: &Shape, sites: &Arc<ActiveSites>) -> Result<ActiveGeometry> {
    let m = sites.len();
    let &[1, c_in, xm, 1, 1] = xs.dims() else {
        return Err(invalid(
            "active-site features",
            format!("expected (1, C, {m}, 1, 1), got {xs:?}"),
        ));
    };
    if xm != m {
        return Err(invalid(
            "active-site features",
            format!("{xs:?} for an active set of {m} sites"),
        ));
    }
    let k = sites.kernel();
    let &[c_out, kc_in, kd, kh, kw] = kernel.dims() else {
        return Err(invalid(
            "kernel",
            format!("expected (C_out, C_in, {k}, {k}, {k}), got {kernel:?}"),
        ));
    };
    if [kd, kh, kw] != [k; 3] || kc_in != c_in || c_out == 0 || c_in == 0 {
        return Err(invalid(
            "kernel",
            format!("expected (C_out, {c_in}, {k}, {k}, {k}) for the active set, got {kernel:?}"),
        ));
    }
    Ok(ActiveGeometry {
        c_in,
        c_out,
        sites: Arc::clone(sites),
    })
}

/// The parameters every op carries: zero padding per axis `[D, H, W]` and the stride.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Spec {
    padding: [usize; 3],
    stride: usize,
}

impl Spec {
    /// The same padding on every axis.
    fn uniform(cfg: ConvConfig) -> Self {
        Self {
            padding: [cfg.padding; 3],
            stride: cfg.stride,
        }
    }
}

/// Checks the shapes and returns the geometry of `conv(xs, kernel)`.
fn geometry(xs: &Shape, kernel: &Shape, spec: Spec) -> Result<Geometry> {
    let &[batch, c_in, d, h, w] = xs.dims() else {
        return Err(invalid(
            "input",
            format!("expected (N, C, D, H, W), got {xs:?}"),
        ));
    };
    let &[c_out, kc_in, kd, kh, kw] = kernel.dims() else {
        return Err(invalid(
            "kernel",
            format!("expected (C_out, C_in, kd, kh, kw), got {kernel:?}"),
        ));
    };
    if [c_out, kc_in, kd, kh, kw].contains(&0) {
        return Err(invalid(
            "kernel",
            format!("needs at least one channel each way and one tap per axis, got {kernel:?}"),
        ));
    }
    if kc_in != c_in {
        return Err(invalid(
            "kernel",
            format!("kernel {kernel:?} expects {kc_in} input channels, input {xs:?} has {c_in}"),
        ));
    }
    if spec.stride == 0 {
        return Err(invalid("stride", "must be at least 1"));
    }
    let (input, taps) = ([d, h, w], [kd, kh, kw]);
    if (0..3).any(|a| input[a] + 2 * spec.padding[a] < taps[a]) {
        return Err(invalid(
            "input",
            format!(
                "input {xs:?} with padding {:?} is smaller than the kernel {taps:?}",
                spec.padding
            ),
        ));
    }
    Ok(Geometry {
        batch,
        c_in,
        c_out,
        input,
        kernel: taps,
        padding: spec.padding,
        stride: spec.stride,
    })
}

/// Applies one of the ops to contiguous copies of its arguments, tracking the graph.
fn apply(
    a: &Tensor,
    b: &Tensor,
    op: impl CustomOp2 + Send + Sync + 'static,
) -> candle_core::Result<Tensor> {
    a.contiguous()?.apply_op2(&b.contiguous()?, op)
}

/// Errors unless the op's first input has `len` elements (the geometry comes from the other
/// shapes).
fn check_len(name: &'static str, first: &Layout, len: usize) -> candle_core::Result<()> {
    if first.shape().elem_count() != len {
        candle_core::bail!(
            "{name}: first input {:?} has {} elements, the geometry needs {len}",
            first.shape(),
            first.shape().elem_count()
        );
    }
    Ok(())
}

/// The three CPU kernels, each for one geometry.
enum Kernel {
    Forward(Plan),
    GradInput(Plan),
    GradWeight(Plan),
}

impl storage::Kernel for Kernel {
    fn run<T: Element>(&self, a: &[T], b: &[T]) -> candle_core::Result<Vec<T>> {
        Ok(match self {
            Kernel::Forward(plan) => plan.forward(a, b),
            Kernel::GradInput(plan) => plan.grad_input(a, b),
            Kernel::GradWeight(plan) => plan.grad_weight(a, b),
        })
    }
}

/// The grid convolution's three kernels on plain slices, as the ops run them (Winograd where
/// it pays, else im2col): for the fused networks, which run layer after layer on buffers.
pub(crate) mod grid {
    use conv_kernels::{im2col, winograd, Element, Geometry};

    use super::use_winograd;

    /// `conv(x, w)`.
    pub(crate) fn forward<T: Element>(x: &[T], w: &[T], g: &Geometry) -> Vec<T> {
        if use_winograd(g) {
            winograd::forward(x, w, g)
        } else {
            im2col::forward(x, w, g)
        }
    }

    /// The input gradient of `sum(grad_out * conv(x, w))`.
    pub(crate) fn grad_input<T: Element>(grad_out: &[T], w: &[T], g: &Geometry) -> Vec<T> {
        if use_winograd(g) {
            winograd::grad_input(grad_out, w, g)
        } else {
            im2col::grad_input(grad_out, w, g)
        }
    }

    /// The kernel gradient of `sum(grad_out * conv(x, w))`.
    pub(crate) fn grad_weight<T: Element>(x: &[T], grad_out: &[T], g: &Geometry) -> Vec<T> {
        if use_winograd(g) {
            winograd::grad_weight(x, grad_out, g)
        } else {
            im2col::grad_weight(x, grad_out, g)
        }
    }
}

/// Fewest input channels for which a convolution runs on the Winograd kernel. With F(4, 3), the
/// weights transformed for all channel pairs at once and rows split into phases by vector
/// shuffles, Winograd's transforms (3.4 values per voxel and channel with F(4, 3), 8 with the
/// F(2, 3) of small volumes) cost less than im2col's columns (27 per voxel and input channel) down to a few output channels, so the generators'
/// 16-channel layers and their 4-channel last layer gain from it. A first layer of 3-5 input
/// channels does not: its weight gradient would expand all its output gradients' channels for
/// products only 4 wide. Measured on generator steps (5 layers, 2 threads; docs/performance-patch-gan.md,
/// 2026-11-28): with the 4 -> 32 first layer on Winograd too, 0.89-0.92 s at 71^3 against
/// 0.57-0.61 s; with the 32 -> 4 last layer on im2col, 0.65-0.68 s.
const WINOGRAD_MIN_INPUT_CHANNELS: usize = 16;

/// Whether a convolution runs on the Winograd kernel rather than the im2col one.
fn use_winograd(g: &Geometry) -> bool {
    winograd::supports(g) && g.c_in >= WINOGRAD_MIN_INPUT_CHANNELS
}

/// The gradient `compute` gives, if `arg` is part of the autograd graph (a variable or the result
/// of a tracked op); constants (the critic's real images, the generator's input) get none, and
/// their convolutions are skipped.
fn wanted(
    arg: &Tensor,
    compute: impl FnOnce() -> candle_core::Result<Tensor>,
) -> candle_core::Result<Option<Tensor>> {
    wanted_if(arg.track_op(), compute)
}

/// The gradient `compute` gives if `want`.
fn wanted_if(
    want: bool,
    compute: impl FnOnce() -> candle_core::Result<Tensor>,
) -> candle_core::Result<Option<Tensor>> {
    if want {
        compute().map(Some)
    } else {
        Ok(None)
    }
}

/// The grid convolution of `cfg` on CPU storages, as the forward op runs it: for ops that fuse
/// a convolution with what follows it.
pub(crate) fn grid_conv_storage(
    cfg: ConvConfig,
    (s1, l1): (&CpuStorage, &Layout),
    (s2, l2): (&CpuStorage, &Layout),
) -> candle_core::Result<(CpuStorage, Shape)> {
    ConvOp(Domain::Grid(Spec::uniform(cfg))).cpu_fwd(s1, l1, s2, l2)
}

/// The gradients of `sum(grad * conv3d(xs, kernel, cfg))` with respect to `xs` and `kernel`
/// (each only if it is part of the autograd graph), as the forward op's backward pass makes
/// them.
pub(crate) fn grid_conv_grads(
    xs: &Tensor,
    kernel: &Tensor,
    cfg: ConvConfig,
    grad: &Tensor,
) -> candle_core::Result<(Option<Tensor>, Option<Tensor>)> {
    let want = [xs.track_op(), kernel.track_op()];
    grid_conv_grads_wanted(xs, kernel, cfg, grad, want)
}

/// [`grid_conv_grads`] for the gradients `want` asks for (`[xs, kernel]`), whether or not the
/// arguments are part of the autograd graph: for ops that run several layers and keep the
/// inner layers' inputs as plain tensors.
pub(crate) fn grid_conv_grads_wanted(
    xs: &Tensor,
    kernel: &Tensor,
    cfg: ConvConfig,
    grad: &Tensor,
    want: [bool; 2],
) -> candle_core::Result<(Option<Tensor>, Option<Tensor>)> {
    let (xs, kernel) = (xs.contiguous()?, kernel.contiguous()?);
    ConvOp(Domain::Grid(Spec::uniform(cfg))).grads(&xs, &kernel, grad, want)
}

/// Forward op: `(x, kernel) -> y`.
struct ConvOp(Domain);

impl ConvOp {
    /// The backward pass: the input gradient and the kernel gradient of `grad`, if wanted.
    fn grads(
        &self,
        xs: &Tensor,
        kernel: &Tensor,
        grad: &Tensor,
        [want_xs, want_kernel]: [bool; 2],
    ) -> candle_core::Result<(Option<Tensor>, Option<Tensor>)> {
        let grad_xs = wanted_if(want_xs, || {
            apply(
                grad,
                kernel,
                GradInputOp(self.0.clone(), xs.shape().clone()),
            )
        })?;
        let grad_kernel = wanted_if(want_kernel, || {
            apply(
                xs,
                grad,
                GradKernelOp(self.0.clone(), kernel.shape().clone()),
            )
        })?;
        Ok((grad_xs, grad_kernel))
    }
}

impl CustomOp2 for ConvOp {
    fn name(&self) -> &'static str {
        "conv"
    }

    fn cpu_fwd(
        &self,
        s1: &CpuStorage,
        l1: &Layout,
        s2: &CpuStorage,
        l2: &Layout,
    ) -> candle_core::Result<(CpuStorage, Shape)> {
        let g = self.0.checked(l1.shape(), l2.shape())?;
        let shape = g.output_shape();
        let out = storage::run_binary(self.name(), (s1, l1), (s2, l2), &Kernel::Forward(g))?;
        Ok((out, shape))
    }

    fn bwd(
        &self,
        xs: &Tensor,
        kernel: &Tensor,
        _res: &Tensor,
        grad: &Tensor,
    ) -> candle_core::Result<(Option<Tensor>, Option<Tensor>)> {
        self.grads(xs, kernel, grad, [xs.track_op(), kernel.track_op()])
    }
}

/// Input gradient: `(grad_out, kernel) -> grad_x` for an input of the stored shape.
struct GradInputOp(Domain, Shape);

impl CustomOp2 for GradInputOp {
    fn name(&self) -> &'static str {
        "conv-grad-input"
    }

    fn cpu_fwd(
        &self,
        s1: &CpuStorage,
        l1: &Layout,
        s2: &CpuStorage,
        l2: &Layout,
    ) -> candle_core::Result<(CpuStorage, Shape)> {
        let g = self.0.checked(&self.1, l2.shape())?;
        check_len(self.name(), l1, g.output_shape().elem_count())?;
        let out = storage::run_binary(self.name(), (s1, l1), (s2, l2), &Kernel::GradInput(g))?;
        Ok((out, self.1.clone()))
    }

    /// `grad_x` is linear in both arguments: its derivative along `grad_out` is the forward
    /// convolution, along the kernel the kernel gradient.
    fn bwd(
        &self,
        grad_out: &Tensor,
        kernel: &Tensor,
        _res: &Tensor,
        grad: &Tensor,
    ) -> candle_core::Result<(Option<Tensor>, Option<Tensor>)> {
        let along_grad_out = wanted(grad_out, || apply(grad, kernel, ConvOp(self.0.clone())))?;
        let along_kernel = wanted(kernel, || {
            apply(
                grad,
                grad_out,
                GradKernelOp(self.0.clone(), kernel.shape().clone()),
            )
        })?;
        Ok((along_grad_out, along_kernel))
    }
}

/// Kernel gradient: `(x, grad_out) -> grad_kernel` for a kernel of the stored shape.
struct GradKernelOp(Domain, Shape);

impl CustomOp2 for GradKernelOp {
    fn name(&self) -> &'static str {
        "conv-grad-kernel"
    }

    fn cpu_fwd(
        &self,
        s1: &CpuStorage,
        l1: &Layout,
        s2: &CpuStorage,
        l2: &Layout,
    ) -> candle_core::Result<(CpuStorage, Shape)> {
        let g = self.0.checked(l1.shape(), &self.1)?;
        if l2.shape().elem_count() != g.output_shape().elem_count() {
            candle_core::bail!(
                "{}: output gradient {:?} does not match the output {:?}",
                self.name(),
                l2.shape(),
                g.output_shape()
            );
        }
        let out = storage::run_binary(self.name(), (s1, l1), (s2, l2), &Kernel::GradWeight(g))?;
        Ok((out, self.1.clone()))
    }

    /// `grad_kernel` is linear in both arguments: its derivative along `x` is the input
    /// gradient of `grad_out` through the incoming kernel-shaped gradient, along `grad_out` the
    /// forward convolution of `x` with it.
    fn bwd(
        &self,
        xs: &Tensor,
        grad_out: &Tensor,
        _res: &Tensor,
        grad: &Tensor,
    ) -> candle_core::Result<(Option<Tensor>, Option<Tensor>)> {
        let along_xs = wanted(xs, || {
            apply(
                grad_out,
                grad,
                GradInputOp(self.0.clone(), xs.shape().clone()),
            )
        })?;
        let along_grad_out = wanted(grad_out, || apply(xs, grad, ConvOp(self.0.clone())))?;
        Ok((along_xs, along_grad_out))
    }
}

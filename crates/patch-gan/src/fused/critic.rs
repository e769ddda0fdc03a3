//! The patch critic's two training losses, each one op over all of its layers: the WGAN loss
//! of a batch of real and fake inputs ([`critic_loss`]) and the WGAN-GP penalty ([`penalty`]).
//!
//! Built from one op per layer, a critic step made a graph node of every layer's output and of
//! every step of the penalty's chain of transposed convolutions, and candle's backward pass
//! added each node's gradient into a fresh zero tensor (a `zeros_like`, then an `add` on
//! candle's element-wise thread pool, whose worker then spins on a core the convolutions
//! need). Here the layers run on plain buffers inside one op each way, their intermediate
//! values recycled for the next step ([`conv_kernels::recycle`]), and the graph holds the
//! inputs, the packed parameters and the scalar only. The same kernels as the layer-by-layer
//! forms, summed in other orders where a loss is reduced (f64 here): the values agree to the
//! last bits of f32. Differentiable once: the parameters' gradients are made, not differentiated
//! again (`Module::forward` and the generic `gradient_penalty` remain for higher orders).

use std::any::Any;
use std::sync::Mutex;

use candle_core::{CpuStorage, CustomOp3, Layout, Shape, Tensor};
use conv_kernels::{fused, recycle, Element, Geometry};

use crate::conv::op::grid;
use crate::storage::{into_storage, run_pass, run_pass_on, Pass};
use crate::wgan::{GradientNorm, GradientPenalty, NORM_EPS};

/// A critic's layers: every convolution unpadded, stride 1, LeakyReLU after all but the last.
#[derive(Debug, Clone)]
pub(crate) struct Layers {
    /// Each kernel's shape `(C_out, C_in, kd, kh, kw)`, the last one's `C_out` 1.
    pub kernels: Vec<[usize; 5]>,
    /// LeakyReLU's slope.
    pub slope: f64,
}

impl Layers {
    /// The layers' geometries on inputs `(N, C, D, H, W)`.
    fn geometries(&self, batch: usize, input: [usize; 3]) -> Vec<Geometry> {
        let mut dims = input;
        self.kernels
            .iter()
            .map(|&[c_out, c_in, kd, kh, kw]| {
                let g = Geometry {
                    batch,
                    c_in,
                    c_out,
                    input: dims,
                    kernel: [kd, kh, kw],
                    padding: [0; 3],
                    stride: 1,
                };
                dims = g.output();
                g
            })
            .collect()
    }

    /// The first layer's input channels.
    fn c_in(&self) -> usize {
        self.kernels.first().map_or(0, |k| k[1])
    }

    /// Values of every kernel, in order.
    fn kernel_lens(&self) -> impl Iterator<Item = usize> + '_ {
        self.kernels.iter().map(|k| k.iter().product())
    }
}

/// Where each layer's weight and bias lie in a packed parameter vector.
#[derive(Debug, Clone)]
struct Packing {
    weights: Vec<usize>,
    /// One per layer that has its bias in the vector.
    biases: Vec<usize>,
    len: usize,
}

impl Packing {
    /// Every layer's weight then its bias, layer after layer ([`critic_loss`]'s parameters).
    fn interleaved(layers: &Layers) -> Self {
        let (mut weights, mut biases, mut at) = (Vec::new(), Vec::new(), 0);
        for (len, k) in layers.kernel_lens().zip(&layers.kernels) {
            weights.push(at);
            biases.push(at + len);
            at += len + k[0];
        }
        Self {
            weights,
            biases,
            len: at,
        }
    }

    /// Every layer's weight, then the hidden layers' biases ([`penalty`]'s parameters: the
    /// tail's bias does not enter the input gradient).
    fn weights_first(layers: &Layers) -> Self {
        let (mut weights, mut biases, mut at) = (Vec::new(), Vec::new(), 0);
        for len in layers.kernel_lens() {
            weights.push(at);
            at += len;
        }
        for k in &layers.kernels[..layers.kernels.len() - 1] {
            biases.push(at);
            at += k[0];
        }
        Self {
            weights,
            biases,
            len: at,
        }
    }
}

/// Buffers a forward pass leaves for its backward pass, recycled when the op goes.
struct Saved<T: Element>(Vec<Vec<T>>);

impl<T: Element> Drop for Saved<T> {
    fn drop(&mut self) {
        self.0.drain(..).for_each(recycle);
    }
}

/// An op's saved buffers, of whichever element type it ran on.
#[derive(Default)]
struct Slot(Mutex<Option<Box<dyn Any + Send>>>);

impl Slot {
    fn put<T: Element>(&self, buffers: Vec<Vec<T>>) -> candle_core::Result<()> {
        *self.lock()? = Some(Box::new(Saved(buffers)));
        Ok(())
    }

    fn lock(&self) -> candle_core::Result<std::sync::MutexGuard<'_, Option<Box<dyn Any + Send>>>> {
        self.0
            .lock()
            .map_err(|_| candle_core::Error::Msg("critic: saved buffers poisoned".into()))
    }
}

/// `(N, C, D, H, W)` of a lifted input.
fn dims5(shape: &Shape, what: &str) -> candle_core::Result<[usize; 5]> {
    match *shape.dims() {
        [n, c, d, h, w] => Ok([n, c, d, h, w]),
        _ => candle_core::bail!("critic: {what} {shape:?} is not (N, C, D, H, W)"),
    }
}

/// `real` then `fake` as one batch (a recycled buffer).
fn joined<T: Element>(real: &[T], fake: &[T]) -> Vec<T> {
    let mut both = conv_kernels::recycled(real.len() + fake.len());
    both.extend_from_slice(real);
    both.extend_from_slice(fake);
    both
}

/// The hidden layers' outputs `h_1 ..= h_{L-1}` of `x`, each LeakyReLU(conv + bias).
fn hidden<T: Element>(
    x: &[T],
    params: &[T],
    (layers, geometries, packing): (&Layers, &[Geometry], &Packing),
) -> Vec<Vec<T>> {
    let mut outputs: Vec<Vec<T>> = Vec::with_capacity(geometries.len() - 1);
    for (i, g) in geometries[..geometries.len() - 1].iter().enumerate() {
        let input = outputs.last().map_or(x, |h| h.as_slice());
        let z = grid::forward(input, weight(params, packing, g, i), g);
        let bias = &params[packing.biases[i]..][..g.c_out];
        let plane = g.output().iter().product();
        outputs.push(fused::bias_leaky_relu(&z, bias, plane, layers.slope));
        recycle(z);
    }
    outputs
}

/// Layer `i`'s weight in `params`.
fn weight<'a, T>(params: &'a [T], packing: &Packing, g: &Geometry, i: usize) -> &'a [T] {
    &params[packing.weights[i]..][..g.kernel_len()]
}

/// A buffer of `len` copies of `value`.
fn filled<T: Element>(len: usize, value: T) -> Vec<T> {
    let mut v = conv_kernels::recycled(len);
    v.resize(len, value);
    v
}

/// The scalar gradient a backward pass got, as f64.
fn scalar(grad: &Tensor) -> candle_core::Result<f64> {
    grad.to_dtype(candle_core::DType::F64)?.to_scalar::<f64>()
}

/// The tensor of `values` with `shape`, outside the graph.
fn tensor(values: CpuStorage, shape: &Shape) -> Tensor {
    Tensor::from_storage(
        candle_core::Storage::Cpu(values),
        shape.clone(),
        candle_core::op::BackpropOp::none(),
        false,
    )
}

/// The critic's WGAN loss `sum_n weight_n mean(D(x_n))` over `real` and `fake` `(N, C, D, H,
/// W)` (images lifted to depth 1), with `weight_n` `-1 / N_real` for real and `1 / N_fake` for
/// fake inputs, as one op; `params` packs every layer's weight and bias in turn.
pub(crate) fn critic_loss(
    (real, fake): (&Tensor, &Tensor),
    params: &Tensor,
    layers: &Layers,
) -> candle_core::Result<Tensor> {
    let op = CriticLoss {
        layers: layers.clone(),
        packing: Packing::interleaved(layers),
        saved: Slot::default(),
    };
    real.contiguous()?
        .apply_op3(&fake.contiguous()?, &params.contiguous()?, op)
}

/// Every layer's weight then bias, flattened into one vector, for [`critic_loss`].
pub(crate) fn pack_interleaved(
    weights: &[Tensor],
    biases: &[&Tensor],
) -> candle_core::Result<Tensor> {
    let mut parts = Vec::with_capacity(2 * weights.len());
    for (w, b) in weights.iter().zip(biases) {
        parts.extend([w.flatten_all()?, (*b).clone()]);
    }
    Tensor::cat(&parts, 0)
}

/// Every layer's weight, then the hidden layers' biases as constants, for [`penalty`].
pub(crate) fn pack_weights_first(
    weights: &[Tensor],
    biases: &[&Tensor],
) -> candle_core::Result<Tensor> {
    let mut parts = weights
        .iter()
        .map(|w| w.flatten_all())
        .collect::<candle_core::Result<Vec<_>>>()?;
    parts.extend(biases[..biases.len() - 1].iter().map(|b| b.detach()));
    Tensor::cat(&parts, 0)
}

struct CriticLoss {
    layers: Layers,
    packing: Packing,
    saved: Slot,
}

impl CriticLoss {
    /// The geometries of a joint batch of `real` and `fake`, after checking the shapes.
    fn geometries(
        &self,
        real: &Shape,
        fake: &Shape,
        params: &Shape,
    ) -> candle_core::Result<(Vec<Geometry>, usize)> {
        let ([nr, c, d, h, w], [nf, ..]) = (dims5(real, "real")?, dims5(fake, "fake")?);
        if real.dims()[1..] != fake.dims()[1..]
            || c != self.layers.c_in()
            || params.elem_count() != self.packing.len
        {
            candle_core::bail!(
                "critic loss: real {real:?}, fake {fake:?}, parameters {params:?} do not match \
                 the critic's {} input channels",
                self.layers.c_in()
            );
        }
        Ok((self.layers.geometries(nr + nf, [d, h, w]), nr))
    }
}

impl CustomOp3 for CriticLoss {
    fn name(&self) -> &'static str {
        "critic-loss"
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
        let (geometries, n_real) = self.geometries(l1.shape(), l2.shape(), l3.shape())?;
        let pass = LossForward {
            op: self,
            geometries: &geometries,
            n_real,
        };
        let mut out = run_pass(self.name(), &[(s1, l1), (s2, l2), (s3, l3)], &pass)?;
        Ok((out.remove(0), Shape::from(())))
    }

    fn bwd(
        &self,
        real: &Tensor,
        fake: &Tensor,
        params: &Tensor,
        _loss: &Tensor,
        grad: &Tensor,
    ) -> candle_core::Result<(Option<Tensor>, Option<Tensor>, Option<Tensor>)> {
        let (geometries, n_real) = self.geometries(real.shape(), fake.shape(), params.shape())?;
        let want_input = real.track_op() || fake.track_op();
        let pass = LossBackward {
            op: self,
            geometries: &geometries,
            n_real,
            grad: scalar(grad)?,
            want_input,
        };
        let mut out = run_pass_on(self.name(), &[real, fake, params], &pass)?.into_iter();
        let grad_params = tensor(
            out.next().expect("the parameters' gradient"),
            params.shape(),
        );
        let (grad_real, grad_fake) = match (out.next(), out.next()) {
            (Some(r), Some(f)) => (
                real.track_op().then(|| tensor(r, real.shape())),
                fake.track_op().then(|| tensor(f, fake.shape())),
            ),
            _ => (None, None),
        };
        Ok((grad_real, grad_fake, Some(grad_params)))
    }
}

/// Per input of a joint batch, its weight in the loss of one patch map value: `-1 / (N_real
/// P)` for real, `1 / (N_fake P)` for fake, `P` values per map.
fn loss_weights(n_real: usize, batch: usize, patches: usize) -> Vec<f64> {
    (0..batch)
        .map(|n| {
            if n < n_real {
                -1.0 / (n_real * patches) as f64
            } else {
                1.0 / ((batch - n_real) * patches) as f64
            }
        })
        .collect()
}

struct LossForward<'a> {
    op: &'a CriticLoss,
    geometries: &'a [Geometry],
    n_real: usize,
}

impl Pass for LossForward<'_> {
    fn run<T: Element>(&self, inputs: &[&[T]]) -> candle_core::Result<Vec<CpuStorage>> {
        let (op, geometries) = (self.op, self.geometries);
        let (x, params) = (joined(inputs[0], inputs[1]), inputs[2]);
        let outputs = hidden(&x, params, (&op.layers, geometries, &op.packing));
        recycle(x);
        let tail = geometries.len() - 1;
        let g = &geometries[tail];
        let last = outputs.last().expect("at least one hidden layer");
        let maps = grid::forward(last, weight(params, &op.packing, g, tail), g);
        let bias = params[op.packing.biases[tail]].to_f64();
        let patches: usize = g.output().iter().product();
        let weights = loss_weights(self.n_real, g.batch, patches);
        let loss: f64 = maps
            .chunks_exact(patches)
            .zip(&weights)
            .map(|(map, w)| w * map.iter().map(|v| v.to_f64() + bias).sum::<f64>())
            .sum();
        recycle(maps);
        op.saved.put(outputs)?;
        Ok(vec![into_storage(vec![T::from_f64(loss)])])
    }
}

struct LossBackward<'a> {
    op: &'a CriticLoss,
    geometries: &'a [Geometry],
    n_real: usize,
    grad: f64,
    want_input: bool,
}

impl Pass for LossBackward<'_> {
    /// The parameters' gradient, then (if wanted) the real and the fake inputs'.
    fn run<T: Element>(&self, inputs: &[&[T]]) -> candle_core::Result<Vec<CpuStorage>> {
        let (op, geometries) = (self.op, self.geometries);
        let saved = op.saved.lock()?;
        let Some(outputs) = saved.as_ref().and_then(|s| s.downcast_ref::<Saved<T>>()) else {
            candle_core::bail!("critic loss: backward before forward");
        };
        let outputs = &outputs.0;
        let (real, fake, params) = (inputs[0], inputs[1], inputs[2]);
        let x = joined(real, fake);
        let packing = &op.packing;
        let mut grad_params = vec![T::ZERO; packing.len];
        let tail = geometries.len() - 1;
        let g = &geometries[tail];
        let patches: usize = g.output().iter().product();
        let weights = loss_weights(self.n_real, g.batch, patches);
        // The loss's gradient at each patch-map value: its input's weight.
        let mut grad_map = conv_kernels::recycled(g.batch * patches);
        for w in &weights {
            grad_map.extend(std::iter::repeat_n(T::from_f64(self.grad * w), patches));
        }
        let bias_grad: f64 = weights.iter().map(|w| self.grad * w * patches as f64).sum();
        grad_params[packing.biases[tail]] = T::from_f64(bias_grad);
        let tail_grad = grid::grad_weight(&outputs[tail - 1], &grad_map, g);
        write(&mut grad_params, packing.weights[tail], &tail_grad);
        let mut grad = grid::grad_input(&grad_map, weight(params, packing, g, tail), g);
        recycle(grad_map);
        for i in (0..tail).rev() {
            let g = &geometries[i];
            let pre = fused::leaky_relu_grad(&grad, &outputs[i], op.layers.slope);
            recycle(grad);
            let plane = g.output().iter().product();
            let bias_grad = fused::channel_sums(&pre, g.c_out, plane);
            write(&mut grad_params, packing.biases[i], &bias_grad);
            let input = if i == 0 {
                x.as_slice()
            } else {
                &outputs[i - 1]
            };
            let kernel_grad = grid::grad_weight(input, &pre, g);
            write(&mut grad_params, packing.weights[i], &kernel_grad);
            grad = if i > 0 || self.want_input {
                grid::grad_input(&pre, weight(params, packing, g, i), g)
            } else {
                Vec::new()
            };
            recycle(pre);
        }
        recycle(x);
        let mut out = vec![into_storage(grad_params)];
        if self.want_input {
            let (r, f) = grad.split_at(real.len());
            out.extend([into_storage(r.to_vec()), into_storage(f.to_vec())]);
        }
        recycle(grad);
        Ok(out)
    }
}

/// Copies `values` into `packed` from `at` on.
fn write<T: Element>(packed: &mut [T], at: usize, values: &[T]) {
    packed[at..at + values.len()].copy_from_slice(values);
}

/// The WGAN-GP penalty of the critic at `alpha_n real_n + (1 - alpha_n) fake_n` (inputs
/// `(N, C, D, H, W)`, images lifted to depth 1) as one op; `params` packs every layer's weight,
/// then the hidden layers' biases (constants: they do not enter the input gradient).
pub(crate) fn penalty(
    (real, fake): (&Tensor, &Tensor),
    alphas: Vec<f64>,
    params: &Tensor,
    (layers, penalty): (&Layers, GradientPenalty),
) -> candle_core::Result<Tensor> {
    let op = Penalty {
        layers: layers.clone(),
        packing: Packing::weights_first(layers),
        alphas,
        penalty,
        saved: Slot::default(),
    };
    real.detach()
        .contiguous()?
        .apply_op3(&fake.detach().contiguous()?, &params.contiguous()?, op)
}

struct Penalty {
    layers: Layers,
    packing: Packing,
    alphas: Vec<f64>,
    penalty: GradientPenalty,
    saved: Slot,
}

impl Penalty {
    /// The geometries of the mixed batch, after checking the shapes.
    fn geometries(
        &self,
        real: &Shape,
        fake: &Shape,
        params: &Shape,
    ) -> candle_core::Result<Vec<Geometry>> {
        let [n, c, d, h, w] = dims5(real, "real")?;
        if real != fake
            || n != self.alphas.len()
            || c != self.layers.c_in()
            || params.elem_count() != self.packing.len
        {
            candle_core::bail!(
                "gradient penalty: real {real:?}, fake {fake:?}, parameters {params:?} do not \
                 match the critic's {} input channels",
                self.layers.c_in()
            );
        }
        Ok(self.layers.geometries(n, [d, h, w]))
    }
}

impl CustomOp3 for Penalty {
    fn name(&self) -> &'static str {
        "critic-gradient-penalty"
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
        let geometries = self.geometries(l1.shape(), l2.shape(), l3.shape())?;
        let pass = PenaltyForward {
            op: self,
            geometries: &geometries,
        };
        let mut out = run_pass(self.name(), &[(s1, l1), (s2, l2), (s3, l3)], &pass)?;
        Ok((out.remove(0), Shape::from(())))
    }

    fn bwd(
        &self,
        real: &Tensor,
        fake: &Tensor,
        params: &Tensor,
        _value: &Tensor,
        grad: &Tensor,
    ) -> candle_core::Result<(Option<Tensor>, Option<Tensor>, Option<Tensor>)> {
        let geometries = self.geometries(real.shape(), fake.shape(), params.shape())?;
        let pass = PenaltyBackward {
            op: self,
            geometries: &geometries,
            grad: scalar(grad)?,
        };
        let mut out = run_pass_on(self.name(), &[params], &pass)?;
        Ok((None, None, Some(tensor(out.remove(0), params.shape()))))
    }
}

/// `alpha_n real_n + (1 - alpha_n) fake_n`, as `mixed_images` makes it.
fn mixed<T: Element>(real: &[T], fake: &[T], alphas: &[f64]) -> Vec<T> {
    let per = real.len() / alphas.len();
    let mut out = conv_kernels::recycled(real.len());
    for ((r, f), &a) in real.chunks(per).zip(fake.chunks(per)).zip(alphas) {
        let (a, b) = (T::from_f64(a), T::from_f64(1.0 - a));
        out.extend(r.iter().zip(f).map(|(&r, &f)| r * a + f * b));
    }
    out
}

/// The penalty's norms: `(groups, per group)` of the input gradient, each group one norm
/// (a pixel's channels, or a whole input).
struct Norms {
    batch: usize,
    channels: usize,
    plane: usize,
    per_pixel: bool,
}

impl Norms {
    fn of(g: &Geometry, norm: GradientNorm) -> Self {
        Self {
            batch: g.batch,
            channels: g.c_in,
            plane: g.input.iter().product(),
            per_pixel: norm == GradientNorm::PerPixel,
        }
    }

    /// Each group's `sqrt(sum of squares + eps)`, in f64; the groups in order (per pixel:
    /// image by image, pixel by pixel).
    fn norms<T: Element>(&self, grad: &[T]) -> Vec<f64> {
        let mut sums = vec![0f64; self.groups()];
        for n in 0..self.batch {
            for c in 0..self.channels {
                let values = &grad[(n * self.channels + c) * self.plane..][..self.plane];
                if self.per_pixel {
                    let sums = &mut sums[n * self.plane..][..self.plane];
                    for (s, v) in sums.iter_mut().zip(values) {
                        *s += v.to_f64() * v.to_f64();
                    }
                } else {
                    sums[n] += values.iter().map(|v| v.to_f64() * v.to_f64()).sum::<f64>();
                }
            }
        }
        sums.into_iter().map(|s| (s + NORM_EPS).sqrt()).collect()
    }

    fn groups(&self) -> usize {
        if self.per_pixel {
            self.batch * self.plane
        } else {
            self.batch
        }
    }

    /// The group of value `(n, c, p)`.
    fn group(&self, n: usize, p: usize) -> usize {
        if self.per_pixel {
            n * self.plane + p
        } else {
            n
        }
    }
}

struct PenaltyForward<'a> {
    op: &'a Penalty,
    geometries: &'a [Geometry],
}

impl Pass for PenaltyForward<'_> {
    /// The penalty; saves the hidden layers' outputs, the chain's LeakyReLU-masked gradients
    /// (each layer's output gradient) and the input gradient.
    fn run<T: Element>(&self, inputs: &[&[T]]) -> candle_core::Result<Vec<CpuStorage>> {
        let (op, geometries) = (self.op, self.geometries);
        let x = mixed(inputs[0], inputs[1], &op.alphas);
        let params = inputs[2];
        let outputs = hidden(&x, params, (&op.layers, geometries, &op.packing));
        recycle(x);
        // d sum(D) / d (tail output) is all ones.
        let tail = geometries.len() - 1;
        let g = &geometries[tail];
        let ones = filled(g.output_len(), T::ONE);
        let mut grad = grid::grad_input(&ones, weight(params, &op.packing, g, tail), g);
        recycle(ones);
        let mut masked = Vec::with_capacity(tail);
        for i in (0..tail).rev() {
            let g = &geometries[i];
            let pre = fused::leaky_relu_grad(&grad, &outputs[i], op.layers.slope);
            recycle(grad);
            grad = grid::grad_input(&pre, weight(params, &op.packing, g, i), g);
            masked.push(pre);
        }
        masked.reverse();
        let norms = Norms::of(&geometries[0], op.penalty.norm);
        let value = op.penalty.weight
            * norms
                .norms(&grad)
                .iter()
                .map(|m| (m - 1.0).powi(2))
                .sum::<f64>()
            / norms.groups() as f64;
        let mut saved = outputs;
        saved.extend(masked);
        saved.push(grad);
        op.saved.put(saved)?;
        Ok(vec![into_storage(vec![T::from_f64(value)])])
    }
}

struct PenaltyBackward<'a> {
    op: &'a Penalty,
    geometries: &'a [Geometry],
    grad: f64,
}

impl Pass for PenaltyBackward<'_> {
    /// The packed parameters' gradient (zero at the biases).
    fn run<T: Element>(&self, inputs: &[&[T]]) -> candle_core::Result<Vec<CpuStorage>> {
        let (op, geometries) = (self.op, self.geometries);
        let saved = op.saved.lock()?;
        let Some(saved) = saved.as_ref().and_then(|s| s.downcast_ref::<Saved<T>>()) else {
            candle_core::bail!("gradient penalty: backward before forward");
        };
        let tail = geometries.len() - 1;
        let (outputs, rest) = saved.0.split_at(tail);
        let (masked, input_grad) = rest.split_at(tail);
        let input_grad = &input_grad[0];
        let params = inputs[0];
        let packing = &op.packing;
        let mut grad_params = vec![T::ZERO; packing.len];
        // d penalty / d (input gradient): weight / groups * 2 (norm - 1) / norm * value.
        let norms = Norms::of(&geometries[0], op.penalty.norm);
        let group_norms = norms.norms(input_grad);
        let scale = self.grad * op.penalty.weight * 2.0 / norms.groups() as f64;
        let factors: Vec<f64> = group_norms.iter().map(|m| scale * (m - 1.0) / m).collect();
        let mut grad = conv_kernels::recycled(input_grad.len());
        for (i, v) in input_grad.iter().enumerate() {
            let (n, p) = (i / (norms.channels * norms.plane), i % norms.plane);
            grad.push(T::from_f64(factors[norms.group(n, p)] * v.to_f64()));
        }
        // Back along the chain: each layer's transposed convolution, then its mask.
        for (i, g) in geometries[..tail].iter().enumerate() {
            let kernel_grad = grid::grad_weight(&grad, &masked[i], g);
            write(&mut grad_params, packing.weights[i], &kernel_grad);
            let along = grid::forward(&grad, weight(params, packing, g, i), g);
            recycle(grad);
            grad = fused::leaky_relu_grad(&along, &outputs[i], op.layers.slope);
            recycle(along);
        }
        let g = &geometries[tail];
        let ones = filled(g.output_len(), T::ONE);
        let tail_grad = grid::grad_weight(&grad, &ones, g);
        write(&mut grad_params, packing.weights[tail], &tail_grad);
        recycle(ones);
        recycle(grad);
        Ok(vec![into_storage(grad_params)])
    }
}

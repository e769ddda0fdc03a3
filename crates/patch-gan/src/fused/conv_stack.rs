//! A generator's layers in training mode as one op: blocks of grid convolution, BatchNorm (batch
//! statistics) and LeakyReLU, then a last convolution.
//!
//! The same kernels as the layers run one by one (the convolution op and
//! [`super::batch_norm_act`]), with the same bits; what goes is the graph nodes between them.
//! candle's backward pass adds every gradient it meets into a fresh zero tensor of its node's
//! size: a `zeros_like` and an `add` of a whole layer per block, on the calling thread while the
//! kernels' threads waited. Here the gradient flows from layer to layer inside the op: what
//! candle still accumulates is the stack's input and output, and the parameters (packed into
//! one vector, so each parameter's own small gradient too).

use std::sync::{Arc, Mutex};

use candle_core::op::BackpropOp;
use candle_core::{CpuStorage, CustomOp2, CustomOp3, Layout, Shape, Storage, Tensor};

use super::batch_norm::{BatchNormAct, BatchStats, NormStats};
use crate::conv::op::{grid_conv_grads_wanted, grid_conv_storage};
use crate::conv::ConvConfig;

/// One block of a [`conv_norm_stack`]: its convolution's kernel `(C_out, C_in, k, k, k)` and
/// its normalisation's gamma and beta, each `(C_out,)`.
pub(crate) struct StackBlock<'a> {
    pub kernel: &'a Tensor,
    pub gamma: &'a Tensor,
    pub beta: &'a Tensor,
}

/// `conv(h_L, last)` with `h_{i+1} = LeakyReLU_slope(BatchNorm(conv(h_i, kernel_i)))` from
/// `h_0 = xs` over `blocks` (batch statistics: training mode), every convolution with `cfg` and
/// no bias; and each block's statistics. Differentiable once in `xs` and every parameter; CPU
/// only.
pub(crate) fn conv_norm_stack(
    xs: &Tensor,
    blocks: &[StackBlock<'_>],
    last: &Tensor,
    cfg: ConvConfig,
    (eps, slope): (f64, f64),
) -> candle_core::Result<(Tensor, Vec<Option<BatchStats>>)> {
    let mut parts = Vec::with_capacity(3 * blocks.len() + 1);
    let mut layout = Vec::with_capacity(blocks.len() + 1);
    for (i, block) in blocks.iter().enumerate() {
        let channels = match block.kernel.dims() {
            &[c_out, _, _, _, _] => c_out,
            other => candle_core::bail!("conv-norm-stack: block {i}'s kernel {other:?} is not 5D"),
        };
        for (name, t) in [("gamma", block.gamma), ("beta", block.beta)] {
            if t.dims() != [channels] {
                candle_core::bail!(
                    "conv-norm-stack: block {i}'s {name} {:?} should be ({channels},), one per output channel",
                    t.dims()
                );
            }
        }
        layout.push(block.kernel.shape().clone());
        parts.extend([
            block.kernel.flatten_all()?,
            block.gamma.clone(),
            block.beta.clone(),
        ]);
    }
    if last.rank() != 5 {
        candle_core::bail!(
            "conv-norm-stack: the last kernel {:?} is not 5D",
            last.dims()
        );
    }
    layout.push(last.shape().clone());
    parts.push(last.flatten_all()?);
    let params = Tensor::cat(&parts, 0)?;
    let starts = layout
        .iter()
        .scan(0, |at, shape| {
            let start = *at;
            // The kernel, then gamma and beta: one value per output channel each.
            *at += shape.elem_count() + 2 * shape.dims()[0];
            Some(start)
        })
        .collect();
    let op = Arc::new(ConvNormStack {
        cfg,
        kernels: layout,
        starts,
        norms: blocks
            .iter()
            .map(|_| BatchNormAct::new(NormStats::Batch, eps, slope))
            .collect(),
        saved: Mutex::new(None),
    });
    let ys = xs
        .contiguous()?
        .apply_op2(&params, Shared(Arc::clone(&op)))?;
    let stats = op
        .norms
        .iter()
        .map(BatchNormAct::measured)
        .collect::<candle_core::Result<_>>()?;
    Ok((ys, stats))
}

/// The op's state.
struct ConvNormStack {
    cfg: ConvConfig,
    /// The kernels' shapes, the blocks' then the last convolution's.
    kernels: Vec<Shape>,
    /// Where each kernel starts in the packed parameters (a block's gamma and beta follow it).
    starts: Vec<usize>,
    norms: Vec<BatchNormAct>,
    /// What the forward pass leaves for the backward pass, as the graph nodes it replaces held
    /// it.
    saved: Mutex<Option<Saved>>,
}

/// Per block, its convolution's output (the normalisation's input); and the inputs of the
/// convolutions after the first (`h_1 ..= h_L`).
struct Saved {
    convolved: Vec<Tensor>,
    inputs: Vec<Tensor>,
}

/// The op as candle holds it, `(xs, params) -> ys`, sharing its state with
/// [`conv_norm_stack`], which reads the statistics afterwards.
struct Shared(Arc<ConvNormStack>);

impl CustomOp2 for Shared {
    fn name(&self) -> &'static str {
        "conv-batch-norm-leaky-relu-stack"
    }

    fn cpu_fwd(
        &self,
        s1: &CpuStorage,
        l1: &Layout,
        s2: &CpuStorage,
        l2: &Layout,
    ) -> candle_core::Result<(CpuStorage, Shape)> {
        let op = &self.0;
        let blocks = op.norms.len();
        let end = op.starts[blocks];
        let expected = end + op.kernels[blocks].elem_count();
        if !l2.is_contiguous() || l2.shape().elem_count() != expected {
            candle_core::bail!(
                "{}: parameters must be one contiguous ({expected},) tensor, got {:?}",
                self.name(),
                l2.shape()
            );
        }
        let param = |at: usize, shape: &Shape| {
            Layout::contiguous_with_offset(shape, l2.start_offset() + at)
        };
        // The next convolution, of the last block's output (of `xs` before the first block).
        let convolve = |inputs: &[(CpuStorage, Shape)], kernel: &Layout| match inputs.last() {
            None => grid_conv_storage(op.cfg, (s1, l1), (s2, kernel)),
            Some((h, shape)) => {
                grid_conv_storage(op.cfg, (h, &Layout::contiguous(shape)), (s2, kernel))
            }
        };
        let mut convolved = Vec::with_capacity(blocks);
        let mut inputs: Vec<(CpuStorage, Shape)> = Vec::with_capacity(blocks);
        for (i, norm) in op.norms.iter().enumerate() {
            let (at, channels) = (op.starts[i], op.kernels[i].dims()[0]);
            let (z, z_shape) = convolve(&inputs, &param(at, &op.kernels[i]))?;
            let after_kernel = at + op.kernels[i].elem_count();
            let gamma = param(after_kernel, &Shape::from(channels));
            let beta = param(after_kernel + channels, &Shape::from(channels));
            let z_layout = Layout::contiguous(&z_shape);
            inputs.push(norm.cpu_fwd(&z, &z_layout, s2, &gamma, s2, &beta)?);
            convolved.push((z, z_shape));
        }
        let out = convolve(&inputs, &param(end, &op.kernels[blocks]))?;
        let tensor = |(storage, shape): (CpuStorage, Shape)| {
            Tensor::from_storage(Storage::Cpu(storage), shape, BackpropOp::none(), false)
        };
        *lock(&op.saved)? = Some(Saved {
            convolved: convolved.into_iter().map(tensor).collect(),
            inputs: inputs.into_iter().map(tensor).collect(),
        });
        Ok(out)
    }

    fn bwd(
        &self,
        xs: &Tensor,
        params: &Tensor,
        _ys: &Tensor,
        grad: &Tensor,
    ) -> candle_core::Result<(Option<Tensor>, Option<Tensor>)> {
        let op = &self.0;
        let saved = lock(&op.saved)?;
        let saved = saved.as_ref().ok_or_else(|| {
            candle_core::Error::Msg(format!("{}: backward before forward", self.name()))
        })?;
        let want_params = params.track_op();
        // The kernels as plain tensors: the gradients below are made, not differentiated again.
        let params_value = params.detach();
        let kernel = |i: usize| {
            params_value
                .narrow(0, op.starts[i], op.kernels[i].elem_count())?
                .reshape(&op.kernels[i])
        };
        let blocks = op.norms.len();
        let input = |i: usize| if i == 0 { xs } else { &saved.inputs[i - 1] };
        // Gradients of the packed parameters, gathered from the last layer back.
        let mut param_grads = Vec::with_capacity(3 * blocks + 1);
        let want_input = |i: usize| i > 0 || xs.track_op();
        let (mut grad_h, grad_last) = grid_conv_grads_wanted(
            input(blocks),
            &kernel(blocks)?,
            op.cfg,
            grad,
            [want_input(blocks), want_params],
        )?;
        param_grads.extend(grad_last.map(|g| g.flatten_all()).transpose()?);
        for i in (0..blocks).rev() {
            // Every block after the first asks for its input's gradient (`want_input`).
            let grad_out = grad_h.ok_or_else(|| {
                candle_core::Error::Msg(format!("{}: no gradient into block {i}", self.name()))
            })?;
            let [grad_z, grad_gamma, grad_beta] = op.norms[i].grads(
                &saved.convolved[i],
                &grad_out,
                [true, want_params, want_params],
            )?;
            let grad_z = grad_z.ok_or_else(|| {
                candle_core::Error::Msg(format!("{}: no gradient of block {i}", self.name()))
            })?;
            let (grad_in, grad_kernel) = grid_conv_grads_wanted(
                input(i),
                &kernel(i)?,
                op.cfg,
                &grad_z,
                [want_input(i), want_params],
            )?;
            // Pushed in reverse, reversed at the end: beta, gamma, kernel.
            param_grads.extend(grad_beta);
            param_grads.extend(grad_gamma);
            param_grads.extend(grad_kernel.map(|g| g.flatten_all()).transpose()?);
            grad_h = grad_in;
        }
        let grad_params = if want_params {
            param_grads.reverse();
            Some(Tensor::cat(&param_grads, 0)?)
        } else {
            None
        };
        Ok((grad_h.filter(|_| xs.track_op()), grad_params))
    }
}

fn lock(m: &Mutex<Option<Saved>>) -> candle_core::Result<std::sync::MutexGuard<'_, Option<Saved>>> {
    m.lock()
        .map_err(|_| candle_core::Error::Msg("conv-norm-stack: lock poisoned".into()))
}

#[cfg(test)]
mod tests {
    use candle_core::{DType, Var};

    use super::*;
    use crate::conv::op::conv3d;
    use crate::fused::batch_norm_act;
    use crate::fused::tests::{assert_same_values_and_gradients, random};

    /// The stack against its layers run one by one (`conv3d` and `batch_norm_act`): the
    /// same output, statistics and gradients of the input and every parameter, bit for bit (the
    /// same kernels). Three input channels take the im2col kernel in the first layer, the
    /// 16-channel layers the Winograd one.
    #[test]
    fn stack_equals_its_blocks_one_by_one() {
        let (eps, slope) = (1e-5, 0.2);
        let cfg = ConvConfig::default().with_padding(1);
        let var = |shape: &[usize], seed: u64| Var::from_tensor(&random(shape, seed)).unwrap();
        let x = var(&[2, 3, 5, 6, 9], 1);
        let channels = [3, 16, 16];
        let kernels: Vec<Var> = (0..2)
            .map(|i| var(&[channels[i + 1], channels[i], 3, 3, 3], 10 + i as u64))
            .collect();
        let gammas: Vec<Var> = (0..2)
            .map(|i| Var::from_tensor(&(random(&[16], 20 + i) + 1.5).unwrap()).unwrap())
            .collect();
        let betas: Vec<Var> = (0..2).map(|i| var(&[16], 30 + i)).collect();
        let last = var(&[4, 16, 3, 3, 3], 40);
        let weights = random(&[2, 4, 5, 6, 9], 50);

        let blocks: Vec<StackBlock> = (0..2)
            .map(|i| StackBlock {
                kernel: &kernels[i],
                gamma: &gammas[i],
                beta: &betas[i],
            })
            .collect();
        let (fused, fused_stats) = conv_norm_stack(&x, &blocks, &last, cfg, (eps, slope)).unwrap();

        let mut h = x.as_tensor().clone();
        let mut plain_stats = Vec::new();
        for i in 0..2 {
            let convolved = conv3d(&h, &kernels[i], cfg).unwrap();
            let stats = NormStats::Batch;
            let (next, stats) =
                batch_norm_act(&convolved, &gammas[i], &betas[i], stats, eps, slope).unwrap();
            plain_stats.push(stats);
            h = next;
        }
        let plain = conv3d(&h, &last, cfg).unwrap();

        assert_eq!(fused.dtype(), DType::F64);
        assert_eq!(fused_stats, plain_stats);
        assert!(fused_stats.iter().all(Option::is_some));
        let names = [
            "kernel 0", "kernel 1", "gamma 0", "gamma 1", "beta 0", "beta 1",
        ];
        let params = [
            &kernels[0],
            &kernels[1],
            &gammas[0],
            &gammas[1],
            &betas[0],
            &betas[1],
        ];
        let mut vars: Vec<(&str, &Var)> = names.into_iter().zip(params).collect();
        vars.extend([("x", &x), ("last", &last)]);
        assert_same_values_and_gradients((&fused, &plain), &weights, &vars, "stack");
    }

    /// A constant input (the generators' noise) gets no gradient, and its convolution's input
    /// gradient is not made; the parameters' gradients are those of a tracked input.
    #[test]
    fn an_untracked_input_gets_no_gradient() {
        let cfg = ConvConfig::default().with_padding(1);
        let x = random(&[1, 3, 4, 4, 4], 1);
        let kernel = Var::from_tensor(&random(&[5, 3, 3, 3, 3], 2)).unwrap();
        let gamma = Var::from_tensor(&(random(&[5], 3) + 1.5).unwrap()).unwrap();
        let beta = Var::from_tensor(&random(&[5], 4)).unwrap();
        let last = Var::from_tensor(&random(&[2, 5, 3, 3, 3], 5)).unwrap();
        let block = [StackBlock {
            kernel: &kernel,
            gamma: &gamma,
            beta: &beta,
        }];
        let (ys, _) = conv_norm_stack(&x, &block, &last, cfg, (1e-5, 0.2)).unwrap();
        let grads = ys.sqr().unwrap().sum_all().unwrap().backward().unwrap();
        assert!(grads.get(&x).is_none());
        let tracked = Var::from_tensor(&x).unwrap();
        let (ys2, _) = conv_norm_stack(&tracked, &block, &last, cfg, (1e-5, 0.2)).unwrap();
        let grads2 = ys2.sqr().unwrap().sum_all().unwrap().backward().unwrap();
        assert!(grads2.get(&tracked).is_some());
        let values = |grads: &candle_core::backprop::GradStore, var: &Var| {
            let grad = grads.get(var).unwrap().flatten_all().unwrap();
            grad.to_vec1::<f64>().unwrap()
        };
        for var in [&kernel, &gamma, &beta, &last] {
            assert_eq!(values(&grads, var), values(&grads2, var));
        }
    }

    /// Parameters of the wrong shape are errors that name the block and the parameter.
    #[test]
    fn misshapen_parameters_are_named() {
        let cfg = ConvConfig::default().with_padding(1);
        let x = random(&[1, 3, 4, 4, 4], 1);
        let kernel = random(&[5, 3, 3, 3, 3], 2);
        let (gamma, short_beta) = (random(&[5], 3), random(&[4], 4));
        let last = random(&[2, 5, 3, 3, 3], 5);
        let block = [StackBlock {
            kernel: &kernel,
            gamma: &gamma,
            beta: &short_beta,
        }];
        let err = conv_norm_stack(&x, &block, &last, cfg, (1e-5, 0.2)).unwrap_err();
        assert!(err.to_string().contains("block 0's beta [4]"), "{err}");
        let flat = kernel.flatten_all().unwrap();
        let block = [StackBlock {
            kernel: &flat,
            gamma: &gamma,
            beta: &gamma,
        }];
        let err = conv_norm_stack(&x, &block, &last, cfg, (1e-5, 0.2)).unwrap_err();
        assert!(err.to_string().contains("not 5D"), "{err}");
    }
}

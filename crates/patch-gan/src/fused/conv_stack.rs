//! A generator's layers in training mode as one op: blocks of convolution (on the grid or on
//! active sites), BatchNorm (batch statistics) and LeakyReLU, then a last convolution.
//!
//! The same kernels as the layers run one by one (the convolution op and
//! [`super::batch_norm_act`]), with the same bits; what goes is the graph nodes between them.
//! candle's backward pass adds every gradient it meets into a fresh zero tensor of its node's
//! size: a `zeros_like` and an `add` of a whole layer per block, on the calling thread while the
//! kernels' threads waited. Here the layers run on plain buffers and the gradient flows from
//! layer to layer inside the op: what candle still accumulates is the stack's input and output,
//! and the parameters (packed into one vector, so each parameter's own small gradient too).
//! The buffers are recycled for the next step ([`conv_kernels::recycle`]) when the graph goes.

use std::any::Any;
use std::sync::{Arc, Mutex};

use candle_core::{CpuStorage, CustomOp2, Layout, Shape, Tensor};
use conv_kernels::fused::{self, NormParams};
use conv_kernels::{recycle, Element};

use super::batch_norm::BatchStats;
use super::channels_and_plane;
use crate::conv::op::{Domain, Plan};
use crate::storage::{into_storage, run_pass, run_pass_on, Pass};

/// One block of a [`conv_norm_stack`]: its convolution's kernel `(C_out, C_in, k, k, k)` and
/// its normalisation's gamma and beta, each `(C_out,)`.
pub(crate) struct StackBlock<'a> {
    pub kernel: &'a Tensor,
    pub gamma: &'a Tensor,
    pub beta: &'a Tensor,
}

/// `conv(h_L, last)` with `h_{i+1} = LeakyReLU_slope(BatchNorm(conv(h_i, kernel_i)))` from
/// `h_0 = xs` over `blocks` (batch statistics: training mode), every convolution in `domain`
/// and without bias; and each block's statistics. Differentiable once in `xs` and every
/// parameter; CPU only.
pub(crate) fn conv_norm_stack(
    xs: &Tensor,
    blocks: &[StackBlock<'_>],
    last: &Tensor,
    domain: Domain,
    (eps, slope): (f64, f64),
) -> candle_core::Result<(Tensor, Vec<Option<BatchStats>>)> {
    let mut parts = Vec::with_capacity(3 * blocks.len() + 1);
    let mut kernels = Vec::with_capacity(blocks.len() + 1);
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
        kernels.push(block.kernel.shape().clone());
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
    kernels.push(last.shape().clone());
    parts.push(last.flatten_all()?);
    let params = Tensor::cat(&parts, 0)?;
    let starts = kernels
        .iter()
        .scan(0, |at, shape| {
            let start = *at;
            // The kernel, then gamma and beta: one value per output channel each.
            *at += shape.elem_count() + 2 * shape.dims()[0];
            Some(start)
        })
        .collect();
    let op = Arc::new(ConvNormStack {
        domain,
        kernels,
        starts,
        eps,
        slope,
        saved: Mutex::new(None),
    });
    let ys = xs
        .contiguous()?
        .apply_op2(&params, Shared(Arc::clone(&op)))?;
    let stats = lock(&op.saved)?
        .as_ref()
        .map(|saved| saved.stats.iter().cloned().map(Some).collect())
        .unwrap_or_default();
    Ok((ys, stats))
}

/// The op's configuration and state.
struct ConvNormStack {
    domain: Domain,
    /// The kernels' shapes, the blocks' then the last convolution's.
    kernels: Vec<Shape>,
    /// Where each kernel starts in the packed parameters (a block's gamma and beta follow it).
    starts: Vec<usize>,
    eps: f64,
    slope: f64,
    /// What the forward pass leaves for the backward pass.
    saved: Mutex<Option<Saved>>,
}

/// Per block, the normalisation it applied and the batch statistics it measured; and the
/// layers' buffers ([`Buffers`] of the element type the op ran on).
struct Saved {
    norms: Vec<NormParams>,
    stats: Vec<BatchStats>,
    buffers: Box<dyn Any + Send>,
}

/// Per block, its convolution's output (the normalisation's input) and its output (the next
/// convolution's input), recycled when the op goes.
struct Buffers<T: Element> {
    convolved: Vec<Vec<T>>,
    outputs: Vec<Vec<T>>,
}

impl<T: Element> Drop for Buffers<T> {
    fn drop(&mut self) {
        self.convolved
            .drain(..)
            .chain(self.outputs.drain(..))
            .for_each(recycle);
    }
}

impl ConvNormStack {
    /// Each layer's plan for an input of `shape`.
    fn plans(&self, shape: &Shape) -> candle_core::Result<Vec<Plan>> {
        let mut shape = shape.clone();
        self.kernels
            .iter()
            .map(|kernel| {
                let plan = self.domain.plan(&shape, kernel)?;
                shape = plan.output_shape();
                Ok(plan)
            })
            .collect()
    }

    /// Kernel `i` in the packed parameters.
    fn kernel<'a, T>(&self, params: &'a [T], i: usize) -> &'a [T] {
        &params[self.starts[i]..][..self.kernels[i].elem_count()]
    }
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
        let blocks = op.kernels.len() - 1;
        let expected = op.starts[blocks] + op.kernels[blocks].elem_count();
        if l2.shape().elem_count() != expected {
            candle_core::bail!(
                "{}: parameters must be one ({expected},) tensor, got {:?}",
                self.name(),
                l2.shape()
            );
        }
        let plans = op.plans(l1.shape())?;
        let shape = plans[blocks].output_shape();
        let pass = StackForward { op, plans: &plans };
        let mut out = run_pass(self.name(), &[(s1, l1), (s2, l2)], &pass)?;
        Ok((out.remove(0), shape))
    }

    fn bwd(
        &self,
        xs: &Tensor,
        params: &Tensor,
        _ys: &Tensor,
        grad: &Tensor,
    ) -> candle_core::Result<(Option<Tensor>, Option<Tensor>)> {
        let op = &self.0;
        let pass = StackBackward {
            op,
            plans: &op.plans(xs.shape())?,
            want_input: xs.track_op(),
            want_params: params.track_op(),
        };
        let grad = grad.contiguous()?;
        let mut out = run_pass_on(self.name(), &[xs, params, &grad], &pass)?.into_iter();
        let as_tensor = |storage: Option<CpuStorage>, shape: &Shape| {
            storage.map(|s| {
                Tensor::from_storage(
                    candle_core::Storage::Cpu(s),
                    shape.clone(),
                    candle_core::op::BackpropOp::none(),
                    false,
                )
            })
        };
        let grad_params = if pass.want_params {
            as_tensor(out.next(), params.shape())
        } else {
            None
        };
        let grad_xs = if pass.want_input {
            as_tensor(out.next(), xs.shape())
        } else {
            None
        };
        Ok((grad_xs, grad_params))
    }
}

struct StackForward<'a> {
    op: &'a ConvNormStack,
    plans: &'a [Plan],
}

impl Pass for StackForward<'_> {
    fn run<T: Element>(&self, inputs: &[&[T]]) -> candle_core::Result<Vec<CpuStorage>> {
        let (op, plans) = (self.op, self.plans);
        let (xs, params) = (inputs[0], inputs[1]);
        let blocks = plans.len() - 1;
        let mut buffers = Buffers::<T> {
            convolved: Vec::with_capacity(blocks),
            outputs: Vec::with_capacity(blocks),
        };
        let (mut norms, mut stats) = (Vec::with_capacity(blocks), Vec::with_capacity(blocks));
        for (i, plan) in plans[..blocks].iter().enumerate() {
            let input = buffers.outputs.last().map_or(xs, |h| h.as_slice());
            let z = plan.forward(input, op.kernel(params, i));
            let (channels, plane) = channels_and_plane(plan.output_shape().dims());
            let (mean, var): (Vec<f64>, Vec<f64>) = fused::channel_stats(&z, channels, plane)
                .into_iter()
                .unzip();
            let after_kernel = op.starts[i] + op.kernels[i].elem_count();
            let param = |at: usize| {
                params[at..at + channels]
                    .iter()
                    .map(|v| v.to_f64())
                    .collect()
            };
            let norm = NormParams {
                inv_std: var.iter().map(|v| 1.0 / (v + op.eps).sqrt()).collect(),
                mean: mean.clone(),
                gamma: param(after_kernel),
                beta: param(after_kernel + channels),
            };
            buffers
                .outputs
                .push(fused::batch_norm_act(&z, plane, &norm, op.slope));
            buffers.convolved.push(z);
            stats.push(BatchStats {
                mean,
                var,
                count: z_count(plan, channels),
            });
            norms.push(norm);
        }
        let last = buffers.outputs.last().map_or(xs, |h| h.as_slice());
        let ys = plans[blocks].forward(last, op.kernel(params, blocks));
        *lock(&op.saved)? = Some(Saved {
            norms,
            stats,
            buffers: Box::new(buffers),
        });
        Ok(vec![into_storage(ys)])
    }
}

/// Values per channel of a plan's output: what BatchNorm's statistics average over.
fn z_count(plan: &Plan, channels: usize) -> usize {
    plan.output_shape().elem_count() / channels
}

struct StackBackward<'a> {
    op: &'a ConvNormStack,
    plans: &'a [Plan],
    want_input: bool,
    want_params: bool,
}

impl Pass for StackBackward<'_> {
    /// The packed parameters' gradient (if wanted), then the input's (if wanted).
    fn run<T: Element>(&self, inputs: &[&[T]]) -> candle_core::Result<Vec<CpuStorage>> {
        let (op, plans) = (self.op, self.plans);
        let (xs, params, grad) = (inputs[0], inputs[1], inputs[2]);
        let saved = lock(&op.saved)?;
        let Some((saved, buffers)) = saved
            .as_ref()
            .and_then(|s| Some((s, s.buffers.downcast_ref::<Buffers<T>>()?)))
        else {
            candle_core::bail!("conv-norm-stack: backward before forward");
        };
        let blocks = plans.len() - 1;
        let input = |i: usize| if i == 0 { xs } else { &buffers.outputs[i - 1] };
        let mut grad_params = if self.want_params {
            vec![T::ZERO; params.len()]
        } else {
            Vec::new()
        };
        let mut write = |at: usize, values: &[T]| {
            if self.want_params {
                grad_params[at..at + values.len()].copy_from_slice(values);
            }
        };
        if self.want_params {
            write(
                op.starts[blocks],
                &plans[blocks].grad_weight(input(blocks), grad),
            );
        }
        let mut grad_h = plans[blocks].grad_input(grad, op.kernel(params, blocks));
        for i in (0..blocks).rev() {
            let z = &buffers.convolved[i];
            let (channels, plane) = channels_and_plane(plans[i].output_shape().dims());
            let packed = fused::batch_norm_act_backward(
                (z, &grad_h),
                plane,
                &saved.norms[i],
                (true, op.slope),
            );
            recycle(grad_h);
            let (grad_z, gamma_beta) = packed.split_at(z.len());
            if self.want_params {
                write(op.starts[i], &plans[i].grad_weight(input(i), grad_z));
                write(
                    op.starts[i] + op.kernels[i].elem_count(),
                    &gamma_beta[..2 * channels],
                );
            }
            grad_h = if i > 0 || self.want_input {
                plans[i].grad_input(grad_z, op.kernel(params, i))
            } else {
                Vec::new()
            };
            recycle(packed);
        }
        let mut out = Vec::with_capacity(2);
        if self.want_params {
            out.push(into_storage(grad_params));
        }
        if self.want_input {
            out.push(into_storage(grad_h));
        } else {
            recycle(grad_h);
        }
        Ok(out)
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
    use crate::fused::tests::{assert_same_values_and_gradients, random};
    use crate::fused::{batch_norm_act, NormStats};
    use crate::ConvConfig;

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
        let stack = conv_norm_stack(&x, &blocks, &last, Domain::grid(cfg), (eps, slope));
        let (fused, fused_stats) = stack.unwrap();

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
        let domain = || Domain::grid(cfg);
        let (ys, _) = conv_norm_stack(&x, &block, &last, domain(), (1e-5, 0.2)).unwrap();
        let grads = ys.sqr().unwrap().sum_all().unwrap().backward().unwrap();
        assert!(grads.get(&x).is_none());
        let tracked = Var::from_tensor(&x).unwrap();
        let (ys2, _) = conv_norm_stack(&tracked, &block, &last, domain(), (1e-5, 0.2)).unwrap();
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
        let err = conv_norm_stack(&x, &block, &last, Domain::grid(cfg), (1e-5, 0.2)).unwrap_err();
        assert!(err.to_string().contains("block 0's beta [4]"), "{err}");
        let flat = kernel.flatten_all().unwrap();
        let block = [StackBlock {
            kernel: &flat,
            gamma: &gamma,
            beta: &gamma,
        }];
        let err = conv_norm_stack(&x, &block, &last, Domain::grid(cfg), (1e-5, 0.2)).unwrap_err();
        assert!(err.to_string().contains("not 5D"), "{err}");
    }
}

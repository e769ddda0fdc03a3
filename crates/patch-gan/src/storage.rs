//! Getting at the contiguous f32/f64 data of candle CPU storages, for the custom ops' kernels,
//! which run inside rayon's pool ([`in_pool`]).

use std::any::Any;

use candle_core::backend::BackendStorage;
use candle_core::{CpuStorage, Layout, Storage, Tensor};
use conv_kernels::Element;

use crate::pool::in_pool;

/// A kernel over the data of one or two same-dtype tensors, written once for every [`Element`].
pub(crate) trait Kernel: Sync {
    /// `a` is the first input's data, `b` the second's (empty for a one-input op).
    fn run<T: Element>(&self, a: &[T], b: &[T]) -> candle_core::Result<Vec<T>>;
}

/// The contiguous data of a storage, or an error naming the op.
fn contiguous<'a, T>(values: &'a [T], layout: &Layout, op: &str) -> candle_core::Result<&'a [T]> {
    match layout.contiguous_offsets() {
        Some((start, end)) => Ok(&values[start..end]),
        None => candle_core::bail!("{op}: inputs have to be contiguous"),
    }
}

/// Runs `kernel` on one storage (f32 or f64).
pub(crate) fn run_unary(
    name: &'static str,
    (s, l): (&CpuStorage, &Layout),
    kernel: &impl Kernel,
) -> candle_core::Result<CpuStorage> {
    in_pool(|| match s {
        CpuStorage::F32(a) => Ok(CpuStorage::F32(kernel.run(contiguous(a, l, name)?, &[])?)),
        CpuStorage::F64(a) => Ok(CpuStorage::F64(kernel.run(contiguous(a, l, name)?, &[])?)),
        _ => Err(candle_core::Error::UnsupportedDTypeForOp(s.dtype(), name)),
    })
}

/// Runs `kernel` on two storages of the same dtype (f32 or f64).
pub(crate) fn run_binary(
    name: &'static str,
    (s1, l1): (&CpuStorage, &Layout),
    (s2, l2): (&CpuStorage, &Layout),
    kernel: &impl Kernel,
) -> candle_core::Result<CpuStorage> {
    in_pool(|| match (s1, s2) {
        (CpuStorage::F32(a), CpuStorage::F32(b)) => Ok(CpuStorage::F32(
            kernel.run(contiguous(a, l1, name)?, contiguous(b, l2, name)?)?,
        )),
        (CpuStorage::F64(a), CpuStorage::F64(b)) => Ok(CpuStorage::F64(
            kernel.run(contiguous(a, l1, name)?, contiguous(b, l2, name)?)?,
        )),
        (CpuStorage::F32(_) | CpuStorage::F64(_), other) => {
            Err(candle_core::Error::DTypeMismatchBinaryOp {
                lhs: s1.dtype(),
                rhs: other.dtype(),
                op: name,
            })
        }
        _ => Err(candle_core::Error::UnsupportedDTypeForOp(s1.dtype(), name)),
    })
}

/// Work over the data of several same-dtype tensors that makes several results, written once
/// for every [`Element`]: the fused networks' passes.
pub(crate) trait Pass: Sync {
    /// `inputs` are the tensors' data, in order.
    fn run<T: Element>(&self, inputs: &[&[T]]) -> candle_core::Result<Vec<CpuStorage>>;
}

/// Runs `pass` on the data of `inputs` (CPU storages of one dtype, f32 or f64, contiguous),
/// inside rayon's pool.
pub(crate) fn run_pass(
    name: &'static str,
    inputs: &[(&CpuStorage, &Layout)],
    pass: &impl Pass,
) -> candle_core::Result<Vec<CpuStorage>> {
    let dtype = inputs.first().map(|(s, _)| s.dtype());
    if let Some((s, _)) = inputs.iter().find(|(s, _)| Some(s.dtype()) != dtype) {
        return Err(candle_core::Error::DTypeMismatchBinaryOp {
            lhs: dtype.unwrap_or(s.dtype()),
            rhs: s.dtype(),
            op: name,
        });
    }
    in_pool(|| {
        if inputs.iter().all(|(s, _)| matches!(s, CpuStorage::F32(_))) {
            let data = inputs
                .iter()
                .map(|(s, l)| match s {
                    CpuStorage::F32(v) => contiguous(v, l, name),
                    _ => unreachable!("checked: all f32"),
                })
                .collect::<candle_core::Result<Vec<_>>>()?;
            pass.run::<f32>(&data)
        } else if inputs.iter().all(|(s, _)| matches!(s, CpuStorage::F64(_))) {
            let data = inputs
                .iter()
                .map(|(s, l)| match s {
                    CpuStorage::F64(v) => contiguous(v, l, name),
                    _ => unreachable!("checked: all f64"),
                })
                .collect::<candle_core::Result<Vec<_>>>()?;
            pass.run::<f64>(&data)
        } else {
            let dtype = inputs
                .first()
                .map_or(candle_core::DType::F32, |(s, _)| s.dtype());
            Err(candle_core::Error::UnsupportedDTypeForOp(dtype, name))
        }
    })
}

/// [`run_pass`] on tensors (CPU ones, contiguous), as an op's backward pass has them.
pub(crate) fn run_pass_on(
    name: &'static str,
    inputs: &[&Tensor],
    pass: &impl Pass,
) -> candle_core::Result<Vec<CpuStorage>> {
    let guards: Vec<_> = inputs.iter().map(|t| t.storage_and_layout()).collect();
    let storages = guards
        .iter()
        .map(|(storage, layout)| match &**storage {
            Storage::Cpu(cpu) => Ok((cpu, *layout)),
            _ => candle_core::bail!("{name}: runs on the CPU only"),
        })
        .collect::<candle_core::Result<Vec<_>>>()?;
    run_pass(name, &storages, pass)
}

/// `values` as a candle storage.
pub(crate) fn into_storage<T: Element>(values: Vec<T>) -> CpuStorage {
    let values: Box<dyn Any> = Box::new(values);
    match values.downcast::<Vec<f32>>() {
        Ok(v) => CpuStorage::F32(*v),
        Err(other) => CpuStorage::F64(
            *other
                .downcast::<Vec<f64>>()
                .expect("an Element is f32 or f64"),
        ),
    }
}

/// A small f32/f64 storage (per-channel parameters) as f64 values.
pub(crate) fn to_f64_vec(
    name: &'static str,
    (s, l): (&CpuStorage, &Layout),
) -> candle_core::Result<Vec<f64>> {
    match s {
        CpuStorage::F32(a) => Ok(contiguous(a, l, name)?
            .iter()
            .map(|&v| v.to_f64())
            .collect()),
        CpuStorage::F64(a) => Ok(contiguous(a, l, name)?.to_vec()),
        _ => Err(candle_core::Error::UnsupportedDTypeForOp(s.dtype(), name)),
    }
}

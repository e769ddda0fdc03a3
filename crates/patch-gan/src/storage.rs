//! Getting at the contiguous f32/f64 data of candle CPU storages, for the custom ops' kernels.

use candle_core::backend::BackendStorage;
use candle_core::{CpuStorage, Layout};
use conv_kernels::Element;

/// A kernel over the data of one or two same-dtype tensors, written once for every [`Element`].
pub(crate) trait Kernel {
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
    match s {
        CpuStorage::F32(a) => Ok(CpuStorage::F32(kernel.run(contiguous(a, l, name)?, &[])?)),
        CpuStorage::F64(a) => Ok(CpuStorage::F64(kernel.run(contiguous(a, l, name)?, &[])?)),
        _ => Err(candle_core::Error::UnsupportedDTypeForOp(s.dtype(), name)),
    }
}

/// Runs `kernel` on two storages of the same dtype (f32 or f64).
pub(crate) fn run_binary(
    name: &'static str,
    (s1, l1): (&CpuStorage, &Layout),
    (s2, l2): (&CpuStorage, &Layout),
    kernel: &impl Kernel,
) -> candle_core::Result<CpuStorage> {
    match (s1, s2) {
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

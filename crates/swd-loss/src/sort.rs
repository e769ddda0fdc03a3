//! Sorting along the last dimension, differentiably.
//!
//! The permutation is found by a CPU kernel that sorts contiguous (value, index) pairs: candle
//! 0.11's `arg_sort_last_dim` sorts bare indices and looks every value up through them, which
//! is several times slower on long rows. Other devices and dtypes use candle's kernel. The
//! values are then gathered, so gradients flow back through the gather.

use std::cmp::Ordering;

use candle_core::backend::BackendStorage;
use candle_core::{CpuStorage, CustomOp1, DType, Layout, Shape, Tensor, D};
use rayon::prelude::*;

use crate::error::Result;

/// Returns `t` sorted in increasing order along its last dimension (NaN-free input).
pub(crate) fn sort_last_dim(t: &Tensor) -> Result<Tensor> {
    let t = t.contiguous()?;
    let fast = t.device().is_cpu() && matches!(t.dtype(), DType::F32 | DType::F64);
    let order = if fast {
        t.apply_op1_no_bwd(&ArgSortPairs)?
    } else {
        t.arg_sort_last_dim(true)?
    };
    Ok(t.gather(&order, D::Minus1)?)
}

/// The ascending argsort of every row of the last dimension, as `u32`.
struct ArgSortPairs;

impl CustomOp1 for ArgSortPairs {
    fn name(&self) -> &'static str {
        "swd-argsort-pairs"
    }

    fn cpu_fwd(
        &self,
        storage: &CpuStorage,
        layout: &Layout,
    ) -> candle_core::Result<(CpuStorage, Shape)> {
        let (start, end) = layout
            .contiguous_offsets()
            .ok_or(candle_core::Error::RequiresContiguous { op: self.name() })?;
        let row = layout.dims().last().copied().unwrap_or(1);
        let order = match storage {
            CpuStorage::F32(v) => argsort_rows(&v[start..end], row),
            CpuStorage::F64(v) => argsort_rows(&v[start..end], row),
            other => {
                return Err(candle_core::Error::UnsupportedDTypeForOp(
                    other.dtype(),
                    self.name(),
                ))
            }
        };
        Ok((CpuStorage::U32(order), layout.shape().clone()))
    }
}

/// A float with a total order, so the comparison inlines into the sort (a function pointer
/// would cost an indirect call per comparison).
trait SortKey: Copy + Send + Sync {
    fn total_order(&self, other: &Self) -> Ordering;
}

impl SortKey for f32 {
    fn total_order(&self, other: &Self) -> Ordering {
        self.total_cmp(other)
    }
}

impl SortKey for f64 {
    fn total_order(&self, other: &Self) -> Ordering {
        self.total_cmp(other)
    }
}

/// Sorts each `row`-long chunk of `values` by (value, index) pairs, in parallel over rows.
fn argsort_rows<T: SortKey>(values: &[T], row: usize) -> Vec<u32> {
    let mut order = vec![0u32; values.len()];
    if row == 0 {
        return order;
    }
    order
        .par_chunks_mut(row)
        .zip(values.par_chunks(row))
        .for_each_init(Vec::new, |pairs: &mut Vec<(T, u32)>, (out, vals)| {
            pairs.clear();
            pairs.extend(vals.iter().copied().zip(0u32..));
            pairs.sort_unstable_by(|a, b| a.0.total_order(&b.0));
            for (o, (_, i)) in out.iter_mut().zip(pairs.iter()) {
                *o = *i;
            }
        });
    order
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::Device;

    #[test]
    fn sorts_rows_like_candle() -> Result<()> {
        let t = Tensor::new(
            &[[3.0f32, -1.0, 2.0, 0.5], [0.0, 9.0, -7.0, 1.0]],
            &Device::Cpu,
        )?;
        let sorted = sort_last_dim(&t)?;
        assert_eq!(
            sorted.to_vec2::<f32>()?,
            vec![vec![-1.0, 0.5, 2.0, 3.0], vec![-7.0, 0.0, 1.0, 9.0]]
        );
        let t64 = t.to_dtype(DType::F64)?.reshape((2, 1, 4))?;
        assert_eq!(
            sort_last_dim(&t64)?.flatten_all()?.to_vec1::<f64>()?,
            vec![-1.0, 0.5, 2.0, 3.0, -7.0, 0.0, 1.0, 9.0]
        );
        // Other dtypes take candle's kernel.
        let half = t.to_dtype(DType::BF16)?;
        assert_eq!(
            sort_last_dim(&half)?
                .to_dtype(DType::F32)?
                .to_vec2::<f32>()?,
            sorted.to_vec2::<f32>()?
        );
        Ok(())
    }
}

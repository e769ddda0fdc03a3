//! Sorting along the last dimension, differentiably.
//!
//! The permutation is found by a CPU kernel that sorts contiguous (value, index) pairs: candle
//! 0.11's `arg_sort_last_dim` sorts bare indices and looks every value up through them, which
//! is several times slower on long rows. Other devices and dtypes use candle's kernel. The
//! values are then gathered, so gradients flow back through the gather.

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

/// A float sortable by the bits of its total order: `key` maps it to an unsigned integer
/// whose order is `total_cmp`'s (negatives below positives, `-0` below `+0`).
trait SortKey: Copy + Send + Sync {
    type Key: RadixKey;
    fn key(self) -> Self::Key;
}

/// `SortKey` for a float and the unsigned integer of its width: negative floats order
/// backwards in their bits, so all their bits are flipped; positive ones get the sign bit set,
/// which puts them above every negative one.
macro_rules! float_sort_key {
    ($($float:ty => $int:ty),*) => {$(
        impl SortKey for $float {
            type Key = $int;
            fn key(self) -> $int {
                let bits = self.to_bits();
                let sign = 1 << (<$int>::BITS - 1);
                if bits & sign != 0 {
                    !bits
                } else {
                    bits | sign
                }
            }
        }
    )*};
}

float_sort_key!(f32 => u32, f64 => u64);

/// An unsigned key the radix sort splits into [`DIGIT_BITS`]-bit digits.
trait RadixKey: Copy + Ord + Send + Sync {
    const BITS: u32;
    fn digit(self, shift: u32) -> usize;
}

macro_rules! radix_key {
    ($($int:ty),*) => {$(
        impl RadixKey for $int {
            const BITS: u32 = <$int>::BITS;
            fn digit(self, shift: u32) -> usize {
                ((self >> shift) as usize) & (RADIX - 1)
            }
        }
    )*};
}

radix_key!(u32, u64);

/// Bits per radix digit: 11 sorts an f32 in 3 passes with a 2048-entry count table that
/// stays in L1.
const DIGIT_BITS: u32 = 11;
const RADIX: usize = 1 << DIGIT_BITS;

/// Rows shorter than this are sorted by comparison: the radix sort's count tables cost more
/// than they save there.
const RADIX_FROM: usize = 256;

/// Sorts each `row`-long chunk of `values` by (value, index) pairs, in parallel over rows.
/// Ties keep their index order, so the permutation is unique and independent of the
/// algorithm chosen for the row's length.
fn argsort_rows<T: SortKey>(values: &[T], row: usize) -> Vec<u32> {
    let mut order = vec![0u32; values.len()];
    if row == 0 {
        return order;
    }
    order
        .par_chunks_mut(row)
        .zip(values.par_chunks(row))
        .for_each_init(
            || (Vec::new(), Vec::new(), Vec::new()),
            |(pairs, scratch, counts), (out, vals)| {
                pairs.clear();
                pairs.extend(vals.iter().map(|v| v.key()).zip(0u32..));
                if row < RADIX_FROM {
                    pairs.sort_unstable();
                } else {
                    radix_sort(pairs, scratch, counts);
                }
                for (o, (_, i)) in out.iter_mut().zip(pairs.iter()) {
                    *o = *i;
                }
            },
        );
    order
}

/// Stable LSD radix sort of `(key, index)` pairs by key; `scratch` and `counts` are buffers
/// reused between calls (a row's indices are `u32`, so are its counts). Digits that are equal
/// in every key (the high bits of values in a narrow range) are skipped, since such a pass
/// would leave the order unchanged.
fn radix_sort<K: RadixKey>(
    pairs: &mut Vec<(K, u32)>,
    scratch: &mut Vec<(K, u32)>,
    counts: &mut Vec<[u32; RADIX]>,
) {
    let passes = K::BITS.div_ceil(DIGIT_BITS) as usize;
    counts.clear();
    counts.resize(passes, [0; RADIX]);
    // One read of the keys counts the digits of every pass.
    for (key, _) in pairs.iter() {
        for (pass, count) in counts.iter_mut().enumerate() {
            count[key.digit(pass as u32 * DIGIT_BITS)] += 1;
        }
    }
    let n = pairs.len();
    scratch.clear();
    scratch.resize(n, pairs[0]);
    for (pass, count) in counts.iter_mut().enumerate() {
        if count.contains(&(n as u32)) {
            continue;
        }
        // Counts become each digit's first output slot.
        let mut next = 0;
        for c in count.iter_mut() {
            (*c, next) = (next, next + *c);
        }
        let shift = pass as u32 * DIGIT_BITS;
        for &pair in pairs.iter() {
            let slot = &mut count[pair.0.digit(shift)];
            scratch[*slot as usize] = pair;
            *slot += 1;
        }
        std::mem::swap(pairs, scratch);
    }
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

    /// Values with every hard case of a float order: both zeros, infinities, subnormals,
    /// duplicates, and runs that share high bits.
    fn awkward_row(len: usize, salt: u64) -> Vec<f64> {
        let special = [
            0.0,
            -0.0,
            f64::INFINITY,
            f64::NEG_INFINITY,
            1e-310,
            -1e-310,
            1.0,
        ];
        let mut state = salt.wrapping_mul(6_364_136_223_846_793_005) | 1;
        (0..len)
            .map(|i| {
                state = state
                    .wrapping_mul(6_364_136_223_846_793_005)
                    .wrapping_add(1_442_695_040_888_963_407);
                let r = (state >> 11) as f64 / (1u64 << 53) as f64;
                match i % 5 {
                    0 => special[(state >> 60) as usize % special.len()],
                    1 => (r * 8.0).round() - 4.0,
                    _ => (r - 0.5) * 1e3,
                }
            })
            .collect()
    }

    /// The radix path and the comparison path give the permutation of a stable sort by
    /// `total_cmp`, in f32 and f64, on rows below, at and above the radix threshold.
    #[test]
    fn argsort_is_the_stable_total_order_on_every_path() {
        for len in [1, 2, 17, RADIX_FROM - 1, RADIX_FROM, 3000] {
            for salt in 0..3 {
                let row64 = awkward_row(len, salt);
                let row32: Vec<f32> = row64.iter().map(|&v| v as f32).collect();
                let rows = 2;
                let values64: Vec<f64> = row64.iter().chain(row64.iter().rev()).copied().collect();
                let values32: Vec<f32> = row32.iter().chain(row32.iter().rev()).copied().collect();
                let got64 = argsort_rows(&values64, len);
                let got32 = argsort_rows(&values32, len);
                for r in 0..rows {
                    let span = r * len..(r + 1) * len;
                    let mut want64: Vec<u32> = (0..len as u32).collect();
                    want64.sort_by(|&a, &b| {
                        values64[span.start + a as usize]
                            .total_cmp(&values64[span.start + b as usize])
                    });
                    let mut want32: Vec<u32> = (0..len as u32).collect();
                    want32.sort_by(|&a, &b| {
                        values32[span.start + a as usize]
                            .total_cmp(&values32[span.start + b as usize])
                    });
                    assert_eq!(got64[span.clone()], want64[..], "f64 len {len} salt {salt}");
                    assert_eq!(got32[span], want32[..], "f32 len {len} salt {salt}");
                }
            }
        }
    }
}

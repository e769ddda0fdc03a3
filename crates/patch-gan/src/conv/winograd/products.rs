//! The per-position matrix products of the Winograd forward pass (and so of the input
//! gradient), `M = U V` with `U` a `C_out x C_in` block of transformed weights and `V` a
//! `C_in x cols` block of transformed inputs, on an AVX2 and FMA kernel of our own for f32 (the
//! `gemm` crate for f64, on CPUs without AVX2 and FMA, and on CPUs with AVX-512, whose 16-lane
//! kernels `gemm` has and this does not).
//!
//! The matrices are small (32 x 32 by 32 x ~200 in the critics, one product per position, 36
//! positions per chunk) and there are thousands per step: `gemm`'s set-up per call (its
//! thread-local workspace, packing `U` into panels, tails for the 32 rows its 6-row kernel does
//! not divide) was 8% of a 54^2 critic step's samples on an AVX2 machine. Here `U` (4 KiB) is
//! read in place, broadcast a value at a time from L1, and `V` a row of vectors at a time, with
//! no packing: each `2 x 48` block of `M` is 12 vector accumulators over the `C_in` products.
//!
//! The weight gradient's products (`dU += Z V^T`, dot products along the columns) stay on
//! `gemm`: a kernel of 2 x 4 vector accumulators summed across lanes at the end ran at 42-49
//! GFLOP/s alone against `gemm`'s 44-56.

use super::matmul;
use crate::element::Element;

/// `m (rows x ld) = u (rows x inner) * v (inner x ld)`, all row-major, `m` and `v` with rows
/// `ld` apart and `u` with rows `inner` apart. `ld` is a multiple of 8.
///
/// # Safety
/// The pointers must cover the matrices their sizes imply.
pub(super) unsafe fn forward_product<T: Element>(
    (rows, inner, ld): (usize, usize, usize),
    m: *mut T,
    u: *const T,
    v: *const T,
) {
    #[cfg(target_arch = "x86_64")]
    if T::IS_F32 && ld % 8 == 0 && own_kernels() {
        // SAFETY: `T` is f32 (so the casts keep the types), the CPU has AVX2 and FMA, and the
        // caller vouches for the bounds.
        return unsafe { avx2::forward_product(rows, inner, ld, m.cast(), u.cast(), v.cast()) };
    }
    // SAFETY: forwarded from the caller.
    unsafe {
        matmul(
            (rows, ld, inner),
            (m, ld as isize, 1),
            (u, inner as isize, 1),
            (v, ld as isize, 1),
            false,
        )
    }
}

/// Whether this CPU runs [`avx2::forward_product`]: AVX2 and FMA (the two flags are separate),
/// and no AVX-512, where `gemm`'s 16-lane kernels are the faster ones.
#[cfg(target_arch = "x86_64")]
fn own_kernels() -> bool {
    use std::sync::OnceLock;
    static OWN: OnceLock<bool> = OnceLock::new();
    *OWN.get_or_init(|| {
        crate::simd::has_avx2()
            && std::is_x86_feature_detected!("fma")
            && !std::is_x86_feature_detected!("avx512f")
    })
}

#[cfg(target_arch = "x86_64")]
pub(super) mod avx2 {
    use std::arch::x86_64::{
        __m256, _mm256_broadcast_ss, _mm256_fmadd_ps, _mm256_loadu_ps, _mm256_setzero_ps,
        _mm256_storeu_ps,
    };

    /// f32 lanes per vector.
    const LANES: usize = 8;

    /// The main blocks of `m`: 2 rows by 6 vectors (48 columns), 12 accumulators, which with
    /// the 2 broadcasts and the loaded vector take 15 of the 16 registers and keep both FMA
    /// units busy (an accumulator waits 4 cycles between its FMAs; 12 chains cover 2 x 4).
    /// Measured alone on a Zen 3 core, 32 x 32 by 32 x 192: 76-77 GFLOP/s, as 3 x 4; 4 x 2
    /// 70-71; 4 x 3 and 6 x 2 spill accumulators (37-46); `gemm` 66-68.
    const WIDE_ROWS: usize = 2;
    const WIDE: usize = 6;

    /// Rows of the blocks of the last columns (16 or 8 wide): 4, for 8 or 4 accumulators.
    const NARROW_ROWS: usize = 4;

    /// [`super::forward_product`] for f32.
    ///
    /// # Safety
    /// The CPU must have AVX2 and FMA, `ld` must be a multiple of 8, and the pointers must
    /// cover the matrices.
    #[target_feature(enable = "avx2,fma")]
    pub(super) unsafe fn forward_product(
        rows: usize,
        inner: usize,
        ld: usize,
        m: *mut f32,
        u: *const f32,
        v: *const f32,
    ) {
        let shape = (rows, inner, ld);
        let mut col = 0;
        // SAFETY (all three): the blocks' columns lie below `ld`.
        while col + WIDE * LANES <= ld {
            unsafe { column_block::<WIDE_ROWS, WIDE>(shape, col, m, u, v) };
            col += WIDE * LANES;
        }
        // The last 8 to 40 columns (`ld` is a multiple of 8): blocks of 16, then one of 8.
        while col + 2 * LANES <= ld {
            unsafe { column_block::<NARROW_ROWS, 2>(shape, col, m, u, v) };
            col += 2 * LANES;
        }
        if col < ld {
            unsafe { column_block::<NARROW_ROWS, 1>(shape, col, m, u, v) };
        }
    }

    /// The `VECS x 8` columns of `m` from `col` on, every row, `ROWS` rows at a time.
    ///
    /// # Safety
    /// As [`forward_product`], with `col + 8 VECS <= ld`.
    #[target_feature(enable = "avx2,fma")]
    #[inline]
    unsafe fn column_block<const ROWS: usize, const VECS: usize>(
        shape: (usize, usize, usize),
        col: usize,
        m: *mut f32,
        u: *const f32,
        v: *const f32,
    ) {
        let rows = shape.0;
        let mut row = 0;
        // SAFETY (both): the blocks' rows lie below `rows`.
        while row + ROWS <= rows {
            unsafe { block::<ROWS, VECS>(shape, (row, col), m, u, v) };
            row += ROWS;
        }
        while row < rows {
            unsafe { block::<1, VECS>(shape, (row, col), m, u, v) };
            row += 1;
        }
    }

    /// `m[row..row + R][col..col + 8 VECS] = u[row..row + R][..] * v[..][col..col + 8 VECS]`.
    ///
    /// # Safety
    /// As [`forward_product`], with the block inside `m`.
    #[target_feature(enable = "avx2,fma")]
    #[inline]
    unsafe fn block<const R: usize, const VECS: usize>(
        (_, inner, ld): (usize, usize, usize),
        (row, col): (usize, usize),
        m: *mut f32,
        u: *const f32,
        v: *const f32,
    ) {
        let mut acc: [[__m256; VECS]; R] = [[_mm256_setzero_ps(); VECS]; R];
        // SAFETY: every address is inside `u` (rows `row..row + R`, columns below `inner`),
        // `v` (rows below `inner`, columns `col..col + 8 VECS`) or `m`; unaligned loads.
        // The broadcasts first, then one loaded vector at a time: R + 1 registers beside the
        // accumulators (loading all of a row's vectors first spilled 4 x 3's).
        unsafe {
            for k in 0..inner {
                let v_row = v.add(k * ld + col);
                let bs: [__m256; R] =
                    std::array::from_fn(|r| _mm256_broadcast_ss(&*u.add((row + r) * inner + k)));
                for x in 0..VECS {
                    let vx = _mm256_loadu_ps(v_row.add(x * LANES));
                    for r in 0..R {
                        acc[r][x] = _mm256_fmadd_ps(bs[r], vx, acc[r][x]);
                    }
                }
            }
            for (r, acc_r) in acc.iter().enumerate() {
                let m_row = m.add((row + r) * ld + col);
                for (x, &a) in acc_r.iter().enumerate() {
                    _mm256_storeu_ps(m_row.add(x * LANES), a);
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Values in [-1, 1) from a fixed linear congruential sequence.
    fn values(len: usize, seed: u64) -> Vec<f32> {
        let mut state = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (0..len)
            .map(|_| {
                state = state
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                ((state >> 40) as f32 / (1u64 << 24) as f32) * 2.0 - 1.0
            })
            .collect()
    }

    /// Every block shape the kernel has (2 x 6 vectors, 4 x 2 and 4 x 1 at the last columns,
    /// single rows below them) against the sums in f64: rows 1 to 9, `ld` from 8 to 96 (every
    /// remainder of 48), inner sizes 1, 4 and 33. f32 products of values below 1 summed in f32 are
    /// within `inner` ulps of 1 of the exact sum.
    #[test]
    fn products_match_sums_in_f64() {
        for rows in [1, 3, 4, 5, 9] {
            for inner in [1, 4, 33] {
                for ld in [8, 16, 24, 32, 40, 48, 56, 64, 80, 96] {
                    let u = values(rows * inner, 1);
                    let v = values(inner * ld, 2);
                    // A stale value in `m`: the product must overwrite it.
                    let mut m = vec![f32::NAN; rows * ld];
                    // SAFETY: the vectors have exactly the sizes the shape implies.
                    unsafe {
                        forward_product((rows, inner, ld), m.as_mut_ptr(), u.as_ptr(), v.as_ptr())
                    };
                    for r in 0..rows {
                        for c in 0..ld {
                            let exact: f64 = (0..inner)
                                .map(|k| f64::from(u[r * inner + k]) * f64::from(v[k * ld + c]))
                                .sum();
                            let got = f64::from(m[r * ld + c]);
                            let bound = inner as f64 * f64::from(f32::EPSILON);
                            assert!(
                                (got - exact).abs() <= bound,
                                "{rows}x{inner} by {inner}x{ld}: ({r}, {c}) {got} vs {exact}"
                            );
                        }
                    }
                }
            }
        }
    }
}

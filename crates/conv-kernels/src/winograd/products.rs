//! The per-position matrix products of the Winograd passes, on AVX2 and FMA kernels of our own
//! for f32 (the `gemm` crate for f64, on CPUs without AVX2 and FMA, and on CPUs with AVX-512,
//! whose 16-lane kernels `gemm` has and these do not):
//!
//! - forward (and input gradient): `M = U V`, `U` a `C_out x C_in` block of transformed
//!   weights, `V` a `C_in x cols` block of transformed inputs;
//! - weight gradient: `dU (+)= Z V^T`, `Z` a `C_out x cols` block of expanded output gradients
//!   (on `gemm` also where `C_in` is not a multiple of 8).
//!
//! The matrices are small (32 x 32 by 32 x 150-200 in the generators and critics, one product
//! per transformed position, 36 or 216 positions with F(4, 3)) and there are thousands per step: `gemm`'s set-up
//! per call (its thread-local workspace, packing into panels, tails for the 32 rows its 6-row
//! kernel does not divide) was 8% of a 54^2 critic step's samples on an AVX2 machine, and its
//! weight-gradient products ran at half the rate of its forward ones in a 40^3 generator step.
//! Here the left operand is read in place, broadcast a value at a time from L1, and the right
//! one a row of vectors at a time, with no packing: each `2 x 48` block of the result is 12
//! vector accumulators. The weight gradient's `V^T` is made first, 8 x 8 values at a time
//! (`C_in x cols` values against `C_out x C_in x cols` products), so that its products are of
//! the same kind.

use gemm::Parallelism;

use crate::element::Element;
use crate::isa::Isa;

/// `m (rows x ld) = u (rows x inner) * v (inner x ld)`, all row-major, `m` and `v` with rows
/// `ld` apart and `u` with rows `inner` apart, on the kernel of `isa`. `ld` is a multiple of 8.
///
/// # Safety
/// The pointers must cover the matrices their sizes imply, and `isa` must be one this CPU runs.
pub(super) unsafe fn forward_product<T: Element>(
    isa: Isa,
    (rows, inner, ld): (usize, usize, usize),
    m: *mut T,
    u: *const T,
    v: *const T,
) {
    #[cfg(target_arch = "x86_64")]
    if T::IS_F32 && ld % 8 == 0 && own_kernels(isa) {
        let product = avx2::Product {
            shape: (rows, inner, ld),
            m: (m.cast(), ld),
            u: (u.cast(), inner),
            v: (v.cast(), ld),
            accumulate: false,
        };
        // SAFETY: `T` is f32 (so the casts keep the types), the CPU has AVX2 and FMA, and the
        // caller vouches for the bounds.
        return unsafe { avx2::product(product) };
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

/// `du (rows x inner) = z (rows x cols) * v (inner x cols)^T`, or `+=` with `accumulate`; `du`
/// row-major with rows `inner` apart, `z` and `v` with rows `ld` apart (only their first `cols`
/// columns are read), on the kernel of `isa`. `transposed` is scratch for `v^T`.
///
/// # Safety
/// The pointers must cover the matrices their sizes imply, and `isa` must be one this CPU runs.
pub(super) unsafe fn weight_product<T: Element>(
    isa: Isa,
    (rows, inner, cols, ld): (usize, usize, usize, usize),
    (du, accumulate): (*mut T, bool),
    z: *const T,
    v: *const T,
    transposed: &mut Vec<T>,
) {
    #[cfg(target_arch = "x86_64")]
    if T::IS_F32 && inner % 8 == 0 && own_kernels(isa) {
        crate::scratch::at_least(transposed, cols * inner);
        let vt: *mut f32 = transposed.as_mut_ptr().cast();
        let product = avx2::Product {
            shape: (rows, cols, inner),
            m: (du.cast(), inner),
            u: (z.cast(), ld),
            v: (vt.cast_const(), inner),
            accumulate,
        };
        // SAFETY: as in `forward_product`; `transposed` has room for `v^T`.
        return unsafe {
            avx2::transpose((v.cast(), ld), (inner, cols), vt);
            avx2::product(product)
        };
    }
    // The scratch is the AVX2 branch's only.
    let _ = transposed;
    // SAFETY: forwarded from the caller.
    unsafe {
        matmul(
            (rows, inner, cols),
            (du, inner as isize, 1),
            (z, ld as isize, 1),
            (v, 1, ld as isize),
            accumulate,
        )
    }
}

/// `dst (m x n) = lhs (m x k) * rhs (k x n)` (or `+=` with `accumulate`) on `gemm`, for f64 and
/// the CPUs the kernels below do not run on; row and column strides given as `(row, col)`.
///
/// # Safety
/// The pointers must cover the matrices their strides and sizes imply.
#[allow(clippy::too_many_arguments)]
unsafe fn matmul<T: Element>(
    (m, n, k): (usize, usize, usize),
    dst: (*mut T, isize, isize),
    lhs: (*const T, isize, isize),
    rhs: (*const T, isize, isize),
    accumulate: bool,
) {
    // SAFETY: forwarded from the caller.
    unsafe {
        gemm::gemm(
            m,
            n,
            k,
            dst.0,
            dst.2,
            dst.1,
            accumulate,
            lhs.0,
            lhs.2,
            lhs.1,
            rhs.0,
            rhs.2,
            rhs.1,
            if accumulate { T::ONE } else { T::ZERO },
            T::ONE,
            false,
            false,
            false,
            Parallelism::None,
        )
    }
}

/// Whether a pass on `isa` runs the f32 kernels of this module: on AVX2 and FMA without
/// AVX-512, where `gemm`'s 16-lane kernels are the faster ones (measured:
/// docs/journal/2026-11-performance-patch-gan.md, 2026-12-02).
pub(super) fn own_kernels(isa: Isa) -> bool {
    cfg!(target_arch = "x86_64") && isa == Isa::Avx2
}

#[cfg(target_arch = "x86_64")]
mod avx2 {
    use std::arch::x86_64::{
        __m256, _mm256_add_ps, _mm256_broadcast_ss, _mm256_fmadd_ps, _mm256_loadu_ps,
        _mm256_permute2f128_ps, _mm256_setzero_ps, _mm256_shuffle_ps, _mm256_storeu_ps,
        _mm256_unpackhi_ps, _mm256_unpacklo_ps,
    };

    /// f32 lanes per vector.
    const LANES: usize = 8;

    /// The main blocks of `m`: 2 rows by 6 vectors (48 columns), 12 accumulators, which with
    /// the 2 broadcasts and the loaded vector take 15 of the 16 registers and keep both FMA
    /// units busy (an accumulator waits 4 cycles between its FMAs; 12 chains cover 2 x 4).
    /// Measured alone on a Zen 3 core, 32 x 32 by 32 x 192 (a timing loop in a throwaway test,
    /// not kept): 76-77 GFLOP/s, as 3 x 4; 4 x 2 70-71; 4 x 3 and 6 x 2 spill accumulators
    /// (37-46); `gemm` 66-68.
    const WIDE_ROWS: usize = 2;
    const WIDE: usize = 6;

    /// Rows of the blocks of the last columns (16 or 8 wide): 4, for 8 or 4 accumulators.
    const NARROW_ROWS: usize = 4;

    /// `m (rows x cols) (+)= u (rows x inner) * v (inner x cols)`, each row-major with the row
    /// stride beside its pointer.
    #[derive(Clone, Copy)]
    pub(super) struct Product {
        /// `(rows, inner, cols)`; `cols` a multiple of 8.
        pub(super) shape: (usize, usize, usize),
        pub(super) m: (*mut f32, usize),
        pub(super) u: (*const f32, usize),
        pub(super) v: (*const f32, usize),
        /// Add to `m` instead of writing it.
        pub(super) accumulate: bool,
    }

    /// Computes `p`.
    ///
    /// # Safety
    /// The CPU must have AVX2 and FMA, and the pointers must cover the matrices.
    #[target_feature(enable = "avx2,fma")]
    pub(super) unsafe fn product(p: Product) {
        let cols = p.shape.2;
        let mut col = 0;
        while col + WIDE * LANES <= cols {
            // SAFETY: the block's columns lie below `cols` (the loop's condition); the caller
            // vouches for the CPU and the matrices.
            unsafe { column_block::<WIDE_ROWS, WIDE>(p, col) };
            col += WIDE * LANES;
        }
        // The last 0 to 40 columns (`cols` is a multiple of 8): blocks of 16, then one of 8.
        while col + 2 * LANES <= cols {
            // SAFETY: as above.
            unsafe { column_block::<NARROW_ROWS, 2>(p, col) };
            col += 2 * LANES;
        }
        if col < cols {
            // SAFETY: `col + 8 <= cols`, as `cols` is a multiple of 8; as above otherwise.
            unsafe { column_block::<NARROW_ROWS, 1>(p, col) };
        }
    }

    /// The `VECS x 8` columns of `m` from `col` on, every row, `ROWS` rows at a time.
    ///
    /// # Safety
    /// As [`product`], with `col + 8 VECS <= cols`.
    #[target_feature(enable = "avx2,fma")]
    #[inline]
    unsafe fn column_block<const ROWS: usize, const VECS: usize>(p: Product, col: usize) {
        let rows = p.shape.0;
        let mut row = 0;
        while row + ROWS <= rows {
            // SAFETY: the block's rows lie below `rows` (the loop's condition), its columns
            // below `cols` (the caller's promise), so the block is inside `m`.
            unsafe { block::<ROWS, VECS>(p, (row, col)) };
            row += ROWS;
        }
        while row < rows {
            // SAFETY: as above, for the single row `row < rows`.
            unsafe { block::<1, VECS>(p, (row, col)) };
            row += 1;
        }
    }

    /// `m[row..row + R][col..col + 8 VECS] (+)= u[row..row + R][..] * v[..][col..col + 8 VECS]`.
    ///
    /// # Safety
    /// As [`product`], with the block inside `m`.
    #[target_feature(enable = "avx2,fma")]
    #[inline]
    unsafe fn block<const R: usize, const VECS: usize>(p: Product, (row, col): (usize, usize)) {
        let ((m, m_stride), (u, u_stride), (v, v_stride)) = (p.m, p.u, p.v);
        let mut acc: [[__m256; VECS]; R] = [[_mm256_setzero_ps(); VECS]; R];
        // SAFETY: every address is inside `u` (rows `row..row + R`, columns below `inner`),
        // `v` (rows below `inner`, columns `col..col + 8 VECS`) or `m`; unaligned loads.
        // The broadcasts first, then one loaded vector at a time: R + 1 registers beside the
        // accumulators (loading all of a row's vectors first spilled 4 x 3's).
        unsafe {
            for k in 0..p.shape.1 {
                let v_row = v.add(k * v_stride + col);
                let bs: [__m256; R] =
                    std::array::from_fn(|r| _mm256_broadcast_ss(&*u.add((row + r) * u_stride + k)));
                for x in 0..VECS {
                    let vx = _mm256_loadu_ps(v_row.add(x * LANES));
                    for (acc_r, &b) in acc.iter_mut().zip(&bs) {
                        acc_r[x] = _mm256_fmadd_ps(b, vx, acc_r[x]);
                    }
                }
            }
            for (r, acc_r) in acc.iter().enumerate() {
                let m_row = m.add((row + r) * m_stride + col);
                for (x, &a) in acc_r.iter().enumerate() {
                    let at = m_row.add(x * LANES);
                    let sum = if p.accumulate {
                        _mm256_add_ps(_mm256_loadu_ps(at), a)
                    } else {
                        a
                    };
                    _mm256_storeu_ps(at, sum);
                }
            }
        }
    }

    /// `dst (cols x rows, rows apart) = src^T`, `src` `rows x cols` with its row stride; `rows`
    /// a multiple of 8. Whole 8 x 8 blocks by vector shuffles, the last `cols % 8` columns one
    /// value at a time.
    ///
    /// # Safety
    /// The CPU must have AVX2 and FMA, and the pointers must cover the matrices.
    #[target_feature(enable = "avx2,fma")]
    pub(super) unsafe fn transpose(
        (src, stride): (*const f32, usize),
        (rows, cols): (usize, usize),
        dst: *mut f32,
    ) {
        let whole = cols - cols % LANES;
        // SAFETY: rows below `rows` and columns below `cols` of `src`, their images in `dst`.
        unsafe {
            for r in (0..rows).step_by(LANES) {
                for c in (0..whole).step_by(LANES) {
                    let block: [__m256; LANES] =
                        std::array::from_fn(|i| _mm256_loadu_ps(src.add((r + i) * stride + c)));
                    for (j, column) in transpose_8x8(block).into_iter().enumerate() {
                        _mm256_storeu_ps(dst.add((c + j) * rows + r), column);
                    }
                }
                for c in whole..cols {
                    for i in 0..LANES {
                        *dst.add(c * rows + r + i) = *src.add((r + i) * stride + c);
                    }
                }
            }
        }
    }

    /// The transpose of 8 rows of 8 values: pairs interleaved, then pairs of pairs, then the
    /// 128-bit halves.
    ///
    /// # Safety
    /// The CPU must have AVX2 and FMA.
    #[target_feature(enable = "avx2,fma")]
    #[inline]
    unsafe fn transpose_8x8(r: [__m256; LANES]) -> [__m256; LANES] {
        let t = [
            _mm256_unpacklo_ps(r[0], r[1]),
            _mm256_unpackhi_ps(r[0], r[1]),
            _mm256_unpacklo_ps(r[2], r[3]),
            _mm256_unpackhi_ps(r[2], r[3]),
            _mm256_unpacklo_ps(r[4], r[5]),
            _mm256_unpackhi_ps(r[4], r[5]),
            _mm256_unpacklo_ps(r[6], r[7]),
            _mm256_unpackhi_ps(r[6], r[7]),
        ];
        let q = [
            _mm256_shuffle_ps::<0x44>(t[0], t[2]),
            _mm256_shuffle_ps::<0xEE>(t[0], t[2]),
            _mm256_shuffle_ps::<0x44>(t[1], t[3]),
            _mm256_shuffle_ps::<0xEE>(t[1], t[3]),
            _mm256_shuffle_ps::<0x44>(t[4], t[6]),
            _mm256_shuffle_ps::<0xEE>(t[4], t[6]),
            _mm256_shuffle_ps::<0x44>(t[5], t[7]),
            _mm256_shuffle_ps::<0xEE>(t[5], t[7]),
        ];
        [
            _mm256_permute2f128_ps::<0x20>(q[0], q[4]),
            _mm256_permute2f128_ps::<0x20>(q[1], q[5]),
            _mm256_permute2f128_ps::<0x20>(q[2], q[6]),
            _mm256_permute2f128_ps::<0x20>(q[3], q[7]),
            _mm256_permute2f128_ps::<0x31>(q[0], q[4]),
            _mm256_permute2f128_ps::<0x31>(q[1], q[5]),
            _mm256_permute2f128_ps::<0x31>(q[2], q[6]),
            _mm256_permute2f128_ps::<0x31>(q[3], q[7]),
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The Winograd tests' values in [-1, 1), as f32.
    fn values(len: usize, seed: u64) -> Vec<f32> {
        super::super::tests::values(len, seed)
            .into_iter()
            .map(|v| v as f32)
            .collect()
    }

    /// Every block shape the kernel has (2 x 6 vectors, 4 x 2 and 4 x 1 at the last columns,
    /// single rows below them) against the sums in f64: rows 1 to 9, `ld` from 8 to 96 (every
    /// remainder of 48), inner sizes 1, 4 and 33; on every instruction set this CPU runs (the
    /// AVX2 one is our kernel, the others `gemm`'s). f32 products of values below 1 summed in
    /// f32 are within `inner` ulps of 1 of the exact sum.
    #[test]
    fn products_match_sums_in_f64() {
        for isa in crate::isa::available() {
            products_match_sums_in_f64_on(isa);
        }
    }

    fn products_match_sums_in_f64_on(isa: Isa) {
        for rows in [1, 3, 4, 5, 9] {
            for inner in [1, 4, 33] {
                for ld in [8, 16, 24, 32, 40, 48, 56, 64, 80, 96] {
                    let u = values(rows * inner, 1);
                    let v = values(inner * ld, 2);
                    // A stale value in `m`: the product must overwrite it.
                    let mut m = vec![f32::NAN; rows * ld];
                    let (mp, up, vp) = (m.as_mut_ptr(), u.as_ptr(), v.as_ptr());
                    // SAFETY: the vectors have exactly the sizes the shape implies; the CPU
                    // runs `isa`.
                    unsafe { forward_product(isa, (rows, inner, ld), mp, up, vp) };
                    for r in 0..rows {
                        for c in 0..ld {
                            let exact: f64 = (0..inner)
                                .map(|k| f64::from(u[r * inner + k]) * f64::from(v[k * ld + c]))
                                .sum();
                            let got = f64::from(m[r * ld + c]);
                            let bound = inner as f64 * f64::from(f32::EPSILON);
                            assert!(
                                (got - exact).abs() <= bound,
                                "{isa:?} {rows}x{inner} by {inner}x{ld}: ({r}, {c}) {got} vs {exact}"
                            );
                        }
                    }
                }
            }
        }
    }

    /// The weight gradient's products (`V^T` by whole 8 x 8 blocks and single columns, then
    /// the blocks of the forward kernel, writing and adding) against the sums in f64, with NaN
    /// in the columns between `cols` and `ld`, which must not be read. `inner` 4 takes `gemm`;
    /// every instruction set this CPU runs.
    #[test]
    fn weight_products_match_sums_in_f64() {
        for isa in crate::isa::available() {
            weight_products_match_sums_in_f64_on(isa);
        }
    }

    fn weight_products_match_sums_in_f64_on(isa: Isa) {
        for rows in [1, 4, 5, 32] {
            for inner in [4, 8, 16, 40] {
                for cols in [1usize, 7, 8, 13, 50] {
                    let ld = cols.next_multiple_of(16) + 16;
                    let with_padding = |seed| {
                        let mut m = values(rows.max(inner) * ld, seed);
                        m.iter_mut()
                            .enumerate()
                            .filter(|(i, _)| i % ld >= cols)
                            .for_each(|(_, x)| *x = f32::NAN);
                        m
                    };
                    let (z, v) = (with_padding(3), with_padding(4));
                    let earlier = values(rows * inner, 5);
                    for accumulate in [false, true] {
                        let mut du = if accumulate {
                            earlier.clone()
                        } else {
                            vec![f32::NAN; rows * inner]
                        };
                        let mut transposed = Vec::new();
                        // SAFETY: `z` and `v` have at least `rows` and `inner` rows of `ld`; the
                        // CPU runs `isa`.
                        unsafe {
                            weight_product(
                                isa,
                                (rows, inner, cols, ld),
                                (du.as_mut_ptr(), accumulate),
                                z.as_ptr(),
                                v.as_ptr(),
                                &mut transposed,
                            )
                        };
                        for r in 0..rows {
                            for c in 0..inner {
                                let before = if accumulate {
                                    f64::from(earlier[r * inner + c])
                                } else {
                                    0.0
                                };
                                let exact: f64 = before
                                    + (0..cols)
                                        .map(|k| {
                                            f64::from(z[r * ld + k]) * f64::from(v[c * ld + k])
                                        })
                                        .sum::<f64>();
                                let got = f64::from(du[r * inner + c]);
                                let bound = (cols + 1) as f64 * f64::from(f32::EPSILON);
                                assert!(
                                    (got - exact).abs() <= bound,
                                    "{isa:?} {rows}x{cols} by ({inner}x{cols})^T, accumulate {accumulate}: \
                                     ({r}, {c}) {got} vs {exact}"
                                );
                            }
                        }
                    }
                }
            }
        }
    }
}

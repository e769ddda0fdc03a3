//! The 16-lane AVX-512 build of the row kernels ([`RowKernels`]): f32 rows in vectors of 16,
//! tails under a lane mask instead of scalar loops, and the split of rows into phases (and
//! back) by two-source permutes, 64 values per 8 permutes with F(4, 3). f64 rows (the exactness
//! tests) take the [`Blocks`] build.
//!
//! Compiled for AVX-512 F alone and called from the AVX2 build of the passes: the rest of a
//! chunk's work (loops over rows and tiles, the scalar tiles at a row's ends) stays as the
//! AVX2 build compiles it. The whole chunk compiled for AVX-512 was slower than the AVX2 build
//! (docs/journal/2026-11-performance-patch-gan.md, 2026-11-28, afternoon).

use std::arch::x86_64::{
    __m512, __m512i, __mmask16, _mm512_add_ps, _mm512_mask_storeu_ps, _mm512_maskz_loadu_ps,
    _mm512_mul_ps, _mm512_permutex2var_ps, _mm512_set1_ps, _mm512_setzero_ps, _mm512_sub_ps,
};
use std::ops::{Add, Sub};

use super::rows::{Arith, Blocks, Map, RowKernels};
use crate::element::Element;

/// f32 lanes per vector.
const LANES: usize = 16;

/// The AVX-512 build. A value exists only on a CPU with AVX-512 F ([`Avx512::new`]): its
/// methods run the `avx512f` functions below on that ground.
#[derive(Debug, Clone, Copy)]
pub(super) struct Avx512(());

impl Avx512 {
    /// The build, if this CPU runs it.
    pub(super) fn new() -> Option<Self> {
        std::is_x86_feature_detected!("avx512f").then_some(Self(()))
    }
}

/// `s` as f32 values, if `T` is f32.
fn as_f32<T: Element>(s: &[T]) -> Option<&[f32]> {
    // SAFETY: `T` is f32 (`Element` is sealed to f32 and f64, and only f32 claims IS_F32), so
    // the cast keeps the type, the length and the borrow.
    T::IS_F32.then(|| unsafe { std::slice::from_raw_parts(s.as_ptr().cast::<f32>(), s.len()) })
}

/// `s` as mutable f32 values, if `T` is f32.
fn as_f32_mut<T: Element>(s: &mut [T]) -> Option<&mut [f32]> {
    // SAFETY: as in `as_f32`, with the unique borrow passed on.
    T::IS_F32
        .then(|| unsafe { std::slice::from_raw_parts_mut(s.as_mut_ptr().cast::<f32>(), s.len()) })
}

impl RowKernels for Avx512 {
    fn map_into<T: Element, const I: usize, const O: usize>(
        self,
        srcs: [&[T]; I],
        dst: &mut [T],
        dst_at: [usize; O],
        len: usize,
        map: impl Map<I, O>,
    ) {
        let Some(dst32) = as_f32_mut(dst) else {
            return Blocks.map_into(srcs, dst, dst_at, len, map);
        };
        let srcs = srcs.map(|s| as_f32(s).expect("T is f32, as dst is"));
        for s in &srcs {
            assert!(s.len() >= len, "map_into: a source row shorter than {len}");
        }
        for &at in &dst_at {
            assert!(
                at + len <= dst32.len(),
                "map_into: a destination row out of bounds"
            );
        }
        let base = dst32.as_mut_ptr();
        // SAFETY: the CPU has AVX-512 F (`self` exists); each source has `len` values and each
        // destination row `dst_at[k]..dst_at[k] + len` lies in `dst` (both checked above).
        unsafe {
            map_rows(
                srcs.map(<[f32]>::as_ptr),
                dst_at.map(|at| base.add(at)),
                len,
                map,
            )
        }
    }

    fn deinterleave<T: Element, const M: usize>(
        self,
        dst: &mut [T],
        (stride, count): (usize, usize),
        src: &[T],
        padding: usize,
    ) {
        let (Some(dst32), Some(src32)) = (as_f32_mut(dst), as_f32(src)) else {
            return Blocks.deinterleave::<T, M>(dst, (stride, count), src, padding);
        };
        if count == 0 {
            return;
        }
        assert!(
            (M - 1) * stride + count <= dst32.len(),
            "deinterleave: {M} phases of {count} values {stride} apart do not fit"
        );
        // The tiles that start in the padding, one value at a time (at most one tile: the
        // padding is below the kernel's 3 taps).
        let first_full = padding.div_ceil(M).min(count);
        for k in 0..first_full {
            for p in 0..M {
                let j = (M * k + p).wrapping_sub(padding);
                dst32[p * stride + k] = src32.get(j).copied().unwrap_or(0.0);
            }
        }
        // SAFETY: the CPU has AVX-512 F; the phases' `count` values fit `dst` (checked above),
        // and the loads stay inside `src` (see `split_rows`).
        unsafe {
            split_rows::<M>(
                dst32.as_mut_ptr(),
                (stride, first_full, count),
                src32,
                padding,
            )
        };
    }

    fn interleave<T: Element, const M: usize>(self, dst: &mut [T], phases: &[T], stride: usize) {
        let (Some(dst32), Some(phases32)) = (as_f32_mut(dst), as_f32(phases)) else {
            return Blocks.interleave::<T, M>(dst, phases, stride);
        };
        let tiles = dst32.len().div_ceil(M);
        if tiles == 0 {
            return;
        }
        assert!(
            (M - 1) * stride + tiles <= phases32.len(),
            "interleave: {M} phases of {tiles} values {stride} apart do not fit"
        );
        // SAFETY: the CPU has AVX-512 F; the phases' reads are inside `phases` (checked above),
        // the writes inside `dst` (see `merge_rows`).
        unsafe { merge_rows::<M>(dst32, phases32.as_ptr(), stride) };
    }
}

/// Sixteen f32 lanes. Made only by the loads and zeros of the `avx512f` functions below, so a
/// value exists only on a CPU with AVX-512 F: the operators' `unsafe` intrinsics rest on that.
/// They are `#[inline(always)]`, so inside those functions they compile to one instruction.
#[derive(Clone, Copy)]
struct F32x16(__m512);

impl Add for F32x16 {
    type Output = Self;

    #[inline(always)]
    fn add(self, other: Self) -> Self {
        // SAFETY: the CPU has AVX-512 F (a value of this type exists).
        Self(unsafe { _mm512_add_ps(self.0, other.0) })
    }
}

impl Sub for F32x16 {
    type Output = Self;

    #[inline(always)]
    fn sub(self, other: Self) -> Self {
        // SAFETY: as in `add`.
        Self(unsafe { _mm512_sub_ps(self.0, other.0) })
    }
}

impl Arith for F32x16 {
    #[inline(always)]
    fn times(self, k: f64) -> Self {
        // SAFETY: as in `add`. `k as f32` is `f32::from_f64(k)`, as the scalar build rounds it.
        Self(unsafe { _mm512_mul_ps(self.0, _mm512_set1_ps(k as f32)) })
    }

    #[inline(always)]
    fn zero(self) -> Self {
        // SAFETY: as in `add`.
        Self(unsafe { _mm512_setzero_ps() })
    }
}

/// The mask of the first `n` lanes (all 16 from `n = 16` on).
#[inline(always)]
fn lanes(n: usize) -> __mmask16 {
    if n >= LANES {
        u16::MAX
    } else {
        (1u16 << n) - 1
    }
}

/// A permutation index vector.
#[inline(always)]
fn index(values: [i32; LANES]) -> __m512i {
    // SAFETY: 16 i32 are the 64 bytes of an `__m512i`, which any bits make.
    unsafe { std::mem::transmute::<[i32; LANES], __m512i>(values) }
}

/// `dst[k][i] = map(srcs[0][i], ...)[k]` for `i < len`, 16 lanes at a time, the last vector
/// under a mask.
///
/// # Safety
/// The CPU must have AVX-512 F; every `srcs[k]` must have `len` readable values and every
/// `dst[k]` room for `len` values, the destinations not overlapping the sources.
#[target_feature(enable = "avx512f")]
unsafe fn map_rows<const I: usize, const O: usize>(
    srcs: [*const f32; I],
    dst: [*mut f32; O],
    len: usize,
    map: impl Map<I, O>,
) {
    let mut i = 0;
    while i < len {
        let mask = lanes(len - i);
        let mut values = [F32x16(_mm512_setzero_ps()); I];
        for k in 0..I {
            // SAFETY: lanes `i..min(len, i + 16)` of a source of `len` values (the mask).
            values[k] = F32x16(unsafe { _mm512_maskz_loadu_ps(mask, srcs[k].add(i)) });
        }
        let out = map.apply(values);
        for k in 0..O {
            // SAFETY: the same lanes of a destination with room for `len` values.
            unsafe { _mm512_mask_storeu_ps(dst[k].add(i), mask, out[k].0) };
        }
        i += LANES;
    }
}

/// A permutation table: lane `l` takes `f(l)`, where `f` is one of the tables below (a `const`
/// loop, so that the tables are constants, not computed per call).
const fn table(which: u8) -> [i32; LANES] {
    let mut t = [0i32; LANES];
    let mut l = 0;
    while l < LANES {
        let i = l as i32;
        t[l] = match which {
            // Even and odd lanes of two sources: the 2 phases of 16 tiles.
            EVEN => 2 * i,
            ODD => 2 * i + 1,
            // Phase q (lanes 0-7) and q + 1 (lanes 8-15) of 8 tiles of 4 phases.
            PHASES_01 => 4 * (i % 8) + i / 8,
            PHASES_23 => 4 * (i % 8) + 2 + i / 8,
            // The first (second) halves of two sources, one after the other.
            HALVES_LO => i % 8 + 16 * (i / 8),
            HALVES_HI => 8 + i % 8 + 16 * (i / 8),
            // Lanes 2l and 2l + 1 from lane l (+ 8 for the high half) of the two sources.
            ZIP_LO => i / 2 + 16 * (i % 2),
            ZIP_HI => i / 2 + 8 + 16 * (i % 2),
            // Pairs of lanes from each source in turn: a tile's four phases together.
            PAIRS_LO => 2 * (i / 4) + i % 2 + 16 * ((i / 2) % 2),
            _ => 2 * (i / 4) + i % 2 + 8 + 16 * ((i / 2) % 2),
        };
        l += 1;
    }
    t
}

const EVEN: u8 = 0;
const ODD: u8 = 1;
const PHASES_01: u8 = 2;
const PHASES_23: u8 = 3;
const HALVES_LO: u8 = 4;
const HALVES_HI: u8 = 5;
const ZIP_LO: u8 = 6;
const ZIP_HI: u8 = 7;
const PAIRS_LO: u8 = 8;
const PAIRS_HI: u8 = 9;

/// The tables, made at compile time.
const TABLES: [[i32; LANES]; 10] = [
    table(EVEN),
    table(ODD),
    table(PHASES_01),
    table(PHASES_23),
    table(HALVES_LO),
    table(HALVES_HI),
    table(ZIP_LO),
    table(ZIP_HI),
    table(PAIRS_LO),
    table(PAIRS_HI),
];

/// `a` and `b` permuted by table `which`: lane `l` is lane `t[l]` of `a` (below 16) or of `b`.
#[target_feature(enable = "avx512f")]
#[inline]
fn permute(a: __m512, which: u8, b: __m512) -> __m512 {
    _mm512_permutex2var_ps(a, index(TABLES[which as usize]), b)
}

/// The `M` phases of 16 consecutive tiles (`M x 16` values, tile `t`'s voxel `p` at `M t +
/// p`): phase `p` of tile `t` in lane `t` of vector `p`. With `M = 4`, phases 0-1 and 2-3 of
/// each 8 tiles first, then the two halves joined.
#[target_feature(enable = "avx512f")]
#[inline]
fn split<const M: usize>(v: [__m512; M]) -> [__m512; M] {
    let mut out = v;
    if M == 2 {
        out[0] = permute(v[0], EVEN, v[1]);
        out[1] = permute(v[0], ODD, v[1]);
    } else {
        assert!(M == 4, "F(M, 3) has M = 2 or 4");
        let a = permute(v[0], PHASES_01, v[1]);
        let b = permute(v[0], PHASES_23, v[1]);
        let c = permute(v[2], PHASES_01, v[3]);
        let d = permute(v[2], PHASES_23, v[3]);
        out[0] = permute(a, HALVES_LO, c);
        out[1] = permute(a, HALVES_HI, c);
        out[2] = permute(b, HALVES_LO, d);
        out[3] = permute(b, HALVES_HI, d);
    }
    out
}

/// The inverse of [`split`]: `M` phase vectors of 16 tiles to the tiles' `M x 16` values in
/// order.
#[target_feature(enable = "avx512f")]
#[inline]
fn merge<const M: usize>(p: [__m512; M]) -> [__m512; M] {
    let mut out = p;
    if M == 2 {
        out[0] = permute(p[0], ZIP_LO, p[1]);
        out[1] = permute(p[0], ZIP_HI, p[1]);
    } else {
        assert!(M == 4, "F(M, 3) has M = 2 or 4");
        let a = permute(p[0], ZIP_LO, p[1]);
        let b = permute(p[2], ZIP_LO, p[3]);
        let c = permute(p[0], ZIP_HI, p[1]);
        let d = permute(p[2], ZIP_HI, p[3]);
        out[0] = permute(a, PAIRS_LO, b);
        out[1] = permute(a, PAIRS_HI, b);
        out[2] = permute(c, PAIRS_LO, d);
        out[3] = permute(c, PAIRS_HI, d);
    }
    out
}

/// [`RowKernels::deinterleave`] of tiles `first..count`, 16 tiles at a time: the row's values
/// from voxel `M first - padding` on, zeros past its end (masked loads), split and written
/// under a mask of the block's tiles.
///
/// # Safety
/// The CPU must have AVX-512 F; `dst` must have room for `(M - 1) stride + count` values, and
/// `M first >= padding`.
#[target_feature(enable = "avx512f")]
unsafe fn split_rows<const M: usize>(
    dst: *mut f32,
    (stride, first, count): (usize, usize, usize),
    src: &[f32],
    padding: usize,
) {
    let mut k = first;
    while k < count {
        let tiles = (count - k).min(LANES);
        let start = M * k - padding;
        let available = src.len().saturating_sub(start).min(M * LANES);
        let mut v = [_mm512_setzero_ps(); M];
        for (j, v) in v.iter_mut().enumerate() {
            let n = available.saturating_sub(LANES * j).min(LANES);
            if n > 0 {
                // SAFETY: values `start + 16 j ..+ n` lie in `src` (`n` counts those left).
                *v =
                    unsafe { _mm512_maskz_loadu_ps(lanes(n), src.as_ptr().add(start + LANES * j)) };
            }
        }
        for (p, phase) in split::<M>(v).into_iter().enumerate() {
            // SAFETY: values `p stride + k ..+ tiles` with `k + tiles <= count` (the caller's
            // room).
            unsafe { _mm512_mask_storeu_ps(dst.add(p * stride + k), lanes(tiles), phase) };
        }
        k += tiles;
    }
}

/// [`RowKernels::interleave`], 16 tiles at a time, the last block's phases read and its
/// values written under masks.
///
/// # Safety
/// The CPU must have AVX-512 F, and `phases` must hold `(M - 1) stride + ceil(dst.len() / M)`
/// readable values.
#[target_feature(enable = "avx512f")]
unsafe fn merge_rows<const M: usize>(dst: &mut [f32], phases: *const f32, stride: usize) {
    let (len, out) = (dst.len(), dst.as_mut_ptr());
    let tiles_total = len.div_ceil(M);
    let mut t = 0;
    while t < tiles_total {
        let tiles = (tiles_total - t).min(LANES);
        let mut p = [_mm512_setzero_ps(); M];
        for (q, p) in p.iter_mut().enumerate() {
            // SAFETY: values `q stride + t ..+ tiles` of the phases (the caller's promise).
            *p = unsafe { _mm512_maskz_loadu_ps(lanes(tiles), phases.add(q * stride + t)) };
        }
        let values = (len - M * t).min(M * LANES);
        for (j, v) in merge::<M>(p).into_iter().enumerate() {
            let n = values.saturating_sub(LANES * j).min(LANES);
            if n > 0 {
                // SAFETY: outputs `M t + 16 j ..+ n` lie in `dst` (`n` counts those left).
                unsafe { _mm512_mask_storeu_ps(out.add(M * t + LANES * j), lanes(n), v) };
            }
        }
        t += tiles;
    }
}

#[cfg(test)]
mod tests {
    use super::super::rows::Blocks;
    use super::super::tests::values;
    use super::*;
    use crate::winograd::minimal::{Input, Output, OutputAdjoint, F2, F4};

    fn f32s(len: usize, seed: u64) -> Vec<f32> {
        values(len, seed).into_iter().map(|v| v as f32).collect()
    }

    fn bits(v: &[f32]) -> Vec<u32> {
        v.iter().map(|x| x.to_bits()).collect()
    }

    /// The 16-lane kernels against the blocks' build, bit for bit (the same operations in the
    /// same order), on lengths around the vector width and the blocks' sizes; every source a
    /// different row. Skipped on a CPU without AVX-512.
    #[test]
    fn maps_equal_the_blocks_build_bit_for_bit() {
        let Some(wide) = Avx512::new() else { return };
        for len in [1, 3, 8, 15, 16, 17, 31, 32, 50, 333] {
            let src = f32s(6 * len + 7, len as u64);
            let srcs: [&[f32]; 6] = std::array::from_fn(|k| &src[k * len + 1..]);
            let run = |kernels: &dyn Fn(&mut [f32])| {
                let mut dst = vec![f32::NAN; 6 * len + 3];
                kernels(&mut dst);
                dst
            };
            let at: [usize; 6] = std::array::from_fn(|k| k * len + 2);
            let f4 = Input::<F4, 4, 6>::of();
            let a = run(&|d| wide.map_into(srcs, d, at, len, f4));
            let b = run(&|d| Blocks.map_into(srcs, d, at, len, f4));
            assert_eq!(bits(&a), bits(&b), "F4 input, len {len}");
            let out = Output::<F4, 4, 6>::of();
            let at4: [usize; 4] = std::array::from_fn(|k| k * len);
            let a = run(&|d| wide.map_into(srcs, d, at4, len, out));
            let b = run(&|d| Blocks.map_into(srcs, d, at4, len, out));
            assert_eq!(bits(&a), bits(&b), "F4 output, len {len}");
            let adj = OutputAdjoint::<F2, 2, 4>::of();
            let two: [&[f32]; 2] = [srcs[0], srcs[3]];
            let a = run(&|d| wide.map_into(two, d, at4, len, adj));
            let b = run(&|d| Blocks.map_into(two, d, at4, len, adj));
            assert_eq!(bits(&a), bits(&b), "F2 adjoint, len {len}");
        }
    }

    /// The split into phases and back against the blocks' build, with padding 0-2, rows
    /// shorter and longer than the phases, and counts around 16 tiles.
    #[test]
    fn phases_equal_the_blocks_build() {
        let Some(wide) = Avx512::new() else { return };
        fn check<const M: usize>(wide: Avx512) {
            for len in [1usize, 5, 30, 63, 64, 65, 100, 129] {
                for padding in 0..3 {
                    for count in [1, 15, 16, 17, (len + 2 * padding).div_ceil(M) + 1, 40] {
                        let src = f32s(len, 7);
                        let stride = count + 3;
                        let mut a = vec![f32::NAN; M * stride];
                        let mut b = a.clone();
                        wide.deinterleave::<f32, M>(&mut a, (stride, count), &src, padding);
                        Blocks.deinterleave::<f32, M>(&mut b, (stride, count), &src, padding);
                        let case = format!("M {M}, len {len}, padding {padding}, count {count}");
                        assert_eq!(bits(&a), bits(&b), "split {case}");
                        let out_len = (M * count).min(len);
                        let (mut c, mut d) = (vec![0f32; out_len], vec![1f32; out_len]);
                        wide.interleave::<f32, M>(&mut c, &a, stride);
                        Blocks.interleave::<f32, M>(&mut d, &a, stride);
                        assert_eq!(c, d, "merge {case}");
                    }
                }
            }
        }
        check::<2>(wide);
        check::<4>(wide);
    }
}

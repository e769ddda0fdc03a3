//! Row-wise work of the Winograd kernel: element-wise maps over rows (the transforms along D
//! and H over whole rows, and along W over a chunk's tiles), and the split of rows into phases
//! and back, each in two builds ([`RowKernels`]): fixed-size blocks that the compiler
//! vectorises for whatever instruction set its caller is compiled for (baseline or AVX2), and
//! 16-lane AVX-512 kernels (`avx512`). Both compute the same operations in the same order, so
//! they give the same bits.

use std::ops::{Add, Sub};

use super::RowBuffers;
use crate::element::Element;

/// What the transforms compute with: a value, or (in the 16-lane build) a vector of them.
/// The transforms need sums, differences, products with small constants and zeros only.
pub(super) trait Arith: Copy + Add<Output = Self> + Sub<Output = Self> {
    /// `self` times `k` (rounded to the lane type, as `T::from_f64(k)`).
    fn times(self, k: f64) -> Self;
    /// A zero of this type.
    fn zero(self) -> Self;
}

impl<T: Element> Arith for T {
    #[inline(always)]
    fn times(self, k: f64) -> Self {
        self * T::from_f64(k)
    }

    #[inline(always)]
    fn zero(self) -> Self {
        T::ZERO
    }
}

/// An `I`-to-`O` map applied element by element (lane by lane) to rows: one of Winograd's 1D
/// transforms. A type rather than a closure, so that each build applies it to its own lanes.
pub(super) trait Map<const I: usize, const O: usize>: Copy {
    /// The map of one tuple of values.
    fn apply<A: Arith>(self, values: [A; I]) -> [A; O];
}

/// The row kernels of one build. The kernels take slices and check their bounds; a build is
/// a value, so that the 16-lane one can only exist where the CPU runs it (see `avx512`).
pub(super) trait RowKernels: Copy {
    /// `dst[dst_at[k] + i]` gets component `k` of `map` applied to `(srcs[0][i], srcs[1][i],
    /// ...)` for every `i < len`. The ranges `dst_at[k]..dst_at[k] + len` must lie in `dst` and
    /// not overlap.
    fn map_into<T: Element, const I: usize, const O: usize>(
        self,
        srcs: [&[T]; I],
        dst: &mut [T],
        dst_at: [usize; O],
        len: usize,
        map: impl Map<I, O>,
    );

    /// Splits the row `zeros(padding) ++ src ++ zeros` into `M` phases of `count` values, phase
    /// `p` at `dst[p stride..]`: `dst[p stride + k]` is the padded row's voxel `M k + p` (zero
    /// past either end).
    fn deinterleave<T: Element, const M: usize>(
        self,
        dst: &mut [T],
        stride_count: (usize, usize),
        src: &[T],
        padding: usize,
    );

    /// The inverse of [`RowKernels::deinterleave`] without padding: `dst[x]` is
    /// `phases[(x % M) stride + x / M]`.
    fn interleave<T: Element, const M: usize>(self, dst: &mut [T], phases: &[T], stride: usize);
}

/// The build of fixed-size blocks, vectorised as the caller's instruction set allows.
#[derive(Debug, Clone, Copy)]
pub(super) struct Blocks;

impl RowKernels for Blocks {
    #[inline(always)]
    fn map_into<T: Element, const I: usize, const O: usize>(
        self,
        srcs: [&[T]; I],
        dst: &mut [T],
        dst_at: [usize; O],
        len: usize,
        map: impl Map<I, O>,
    ) {
        map_into(srcs, dst, dst_at, len, |v| map.apply(v))
    }

    #[inline(always)]
    fn deinterleave<T: Element, const M: usize>(
        self,
        dst: &mut [T],
        stride_count: (usize, usize),
        src: &[T],
        padding: usize,
    ) {
        deinterleave::<T, M>(dst, stride_count, src, padding)
    }

    #[inline(always)]
    fn interleave<T: Element, const M: usize>(self, dst: &mut [T], phases: &[T], stride: usize) {
        interleave::<T, M>(dst, phases, stride)
    }
}

/// Values a [`map_into`] step handles at once: fixed-size blocks are what the compiler turns
/// into vector instructions (a plain loop over the rows kept a bounds check per element).
const LANES: usize = 8;

/// [`RowKernels::map_into`] of [`Blocks`], for any function of the values.
#[inline(always)]
fn map_into<T: Element, const I: usize, const O: usize>(
    srcs: [&[T]; I],
    dst: &mut [T],
    dst_at: [usize; O],
    len: usize,
    map: impl Fn([T; I]) -> [T; O],
) {
    // Rows shorter than a block take half blocks (and the shortest single values), so that every
    // copy has a fixed size: a copy of a run-time length is a call to `memmove`.
    if len >= LANES {
        map_blocks::<T, I, O, LANES>(srcs, dst, dst_at, len, map)
    } else if len >= LANES / 2 {
        map_blocks::<T, I, O, { LANES / 2 }>(srcs, dst, dst_at, len, map)
    } else {
        map_blocks::<T, I, O, 1>(srcs, dst, dst_at, len, map)
    }
}

/// [`map_into`] in blocks of `B` values, the last block ending at `len` (it overlaps the one
/// before when `B` does not divide `len`, which only writes the same values again).
#[inline(always)]
fn map_blocks<T: Element, const I: usize, const O: usize, const B: usize>(
    srcs: [&[T]; I],
    dst: &mut [T],
    dst_at: [usize; O],
    len: usize,
    map: impl Fn([T; I]) -> [T; O],
) {
    let srcs = srcs.map(|s| &s[..len]);
    let mut next = 0;
    while next < len {
        let start = next.min(len - B);
        let mut block_in = [[T::ZERO; B]; I];
        let mut block_out = [[T::ZERO; B]; O];
        for (block, src) in block_in.iter_mut().zip(&srcs) {
            block.copy_from_slice(&src[start..start + B]);
        }
        for lane in 0..B {
            let v = map(std::array::from_fn(|k| block_in[k][lane]));
            for k in 0..O {
                block_out[k][lane] = v[k];
            }
        }
        for (&at, block) in dst_at.iter().zip(&block_out) {
            dst[at + start..at + start + B].copy_from_slice(block);
        }
        next = start + B;
    }
}

/// `dst` row `dst_rows[k]` (each `width` long) gets component `k` of `map` applied, element by
/// element, to the rows `src_rows` of `src`.
#[inline(always)]
fn map_rows<T: Element, const I: usize, const O: usize>(
    kernels: impl RowKernels,
    (src, src_rows): (&[T], [usize; I]),
    (dst, dst_rows): (&mut [T], [usize; O]),
    width: usize,
    map: impl Map<I, O>,
) {
    let srcs = src_rows.map(|r| &src[r * width..][..width]);
    kernels.map_into(srcs, dst, dst_rows.map(|r| r * width), width, map)
}

/// [`map_rows`] of any function of the values, in [`Blocks`]: the weights' transforms in f64.
#[inline(always)]
pub(super) fn map_rows_with<T: Element, const I: usize, const O: usize>(
    (src, src_rows): (&[T], [usize; I]),
    (dst, dst_rows): (&mut [T], [usize; O]),
    width: usize,
    map: impl Fn([T; I]) -> [T; O],
) {
    let srcs = src_rows.map(|r| &src[r * width..][..width]);
    map_into(srcs, dst, dst_rows.map(|r| r * width), width, map)
}

/// Applies an `I`-to-`O` map along the D axis (when it has 3 taps) and then the H axis of a
/// block of rows laid out `(d, h, row)`, from `bufs.a` (shape `dims`); returns the new `(d, h)`
/// shape, whose rows are in `bufs.a` again.
#[inline(always)]
pub(super) fn map_d_then_h<T: Element, const I: usize, const O: usize>(
    kernels: impl RowKernels,
    bufs: &mut RowBuffers<T>,
    (dims, taps): ((usize, usize), (usize, usize)),
    width: usize,
    map: impl Map<I, O>,
) -> (usize, usize) {
    let (mut d, h) = dims;
    if taps.0 == 3 {
        for b in 0..h {
            map_rows(
                kernels,
                (&bufs.a, std::array::from_fn(|k| k * h + b)),
                (&mut bufs.b, std::array::from_fn(|k| k * h + b)),
                width,
                map,
            );
        }
        d = O;
        std::mem::swap(&mut bufs.a, &mut bufs.b);
    }
    let mut h2 = h;
    if taps.1 == 3 {
        for a in 0..d {
            map_rows(
                kernels,
                (&bufs.a, std::array::from_fn(|k| a * h + k)),
                (&mut bufs.b, std::array::from_fn(|k| a * O + k)),
                width,
                map,
            );
        }
        h2 = O;
        std::mem::swap(&mut bufs.a, &mut bufs.b);
    }
    (d, h2)
}

/// Tiles a [`deinterleave`] or [`interleave`] step moves at once (then half as many near the
/// ends and in short rows), as a fixed-size transpose the compiler turns into vector shuffles:
/// a loop with `j % M` and `j / M` per voxel was a fifth of the forward pass's time.
const SHUFFLE_TILES: usize = 8;

/// [`RowKernels::deinterleave`] of [`Blocks`].
#[inline(always)]
fn deinterleave<T: Element, const M: usize>(
    dst: &mut [T],
    (stride, count): (usize, usize),
    src: &[T],
    padding: usize,
) {
    let end = padding + src.len();
    let first_full = padding.div_ceil(M);
    let inside =
        |k: usize, tiles: usize| k >= first_full && M * (k + tiles) <= end && k + tiles <= count;
    let mut k = 0;
    while k < count {
        k += if inside(k, SHUFFLE_TILES) {
            deinterleave_block::<T, M, SHUFFLE_TILES>(dst, stride, &src[M * k - padding..], k)
        } else if inside(k, SHUFFLE_TILES / 2) {
            deinterleave_block::<T, M, { SHUFFLE_TILES / 2 }>(
                dst,
                stride,
                &src[M * k - padding..],
                k,
            )
        } else {
            for p in 0..M {
                // Before the row, `j - padding` wraps to a huge index: `get` gives zero.
                let j = (M * k + p).wrapping_sub(padding);
                dst[p * stride + k] = src.get(j).copied().unwrap_or(T::ZERO);
            }
            1
        };
    }
}

/// `B` tiles of [`deinterleave`] from `src`, which starts at the padded row's voxel `M k`;
/// returns `B`.
#[inline(always)]
fn deinterleave_block<T: Element, const M: usize, const B: usize>(
    dst: &mut [T],
    stride: usize,
    src: &[T],
    k: usize,
) -> usize {
    let block = &src[..M * B];
    for p in 0..M {
        let phase: [T; B] = std::array::from_fn(|t| block[M * t + p]);
        dst[p * stride + k..][..B].copy_from_slice(&phase);
    }
    B
}

/// [`RowKernels::interleave`] of [`Blocks`].
#[inline(always)]
fn interleave<T: Element, const M: usize>(dst: &mut [T], phases: &[T], stride: usize) {
    let mut t = 0;
    while M * t < dst.len() {
        let left = dst.len() - M * t;
        t += if left >= M * SHUFFLE_TILES {
            interleave_block::<T, M, SHUFFLE_TILES>(&mut dst[M * t..], phases, stride, t)
        } else if left >= M * SHUFFLE_TILES / 2 {
            interleave_block::<T, M, { SHUFFLE_TILES / 2 }>(&mut dst[M * t..], phases, stride, t)
        } else {
            for (p, out) in dst[M * t..].iter_mut().take(M).enumerate() {
                *out = phases[p * stride + t];
            }
            1
        };
    }
}

/// `B` tiles of [`interleave`] into `dst`, which starts at output `M t`; returns `B`.
#[inline(always)]
fn interleave_block<T: Element, const M: usize, const B: usize>(
    dst: &mut [T],
    phases: &[T],
    stride: usize,
    t: usize,
) -> usize {
    let rows: [[T; B]; M] = std::array::from_fn(|p| {
        let row = &phases[p * stride + t..][..B];
        std::array::from_fn(|i| row[i])
    });
    for (i, out) in dst[..M * B].iter_mut().enumerate() {
        *out = rows[i % M][i / M];
    }
    B
}

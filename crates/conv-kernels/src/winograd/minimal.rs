//! Winograd's 1D transforms F(2, 3) and F(4, 3), and the weights' transform built from them.

use std::marker::PhantomData;
use std::ops::Range;

use rayon::prelude::*;

use super::rows::{map_rows_with, Arith, Map};
use crate::element::Element;
use crate::geometry::Geometry;
use crate::output::{unwritten, SharedMut};
use crate::scratch::{at_least, Pooled};

/// Winograd's F(M, 3) along one axis: `M` outputs of a 3-tap correlation from `N = M + 2`
/// inputs with `N` products. The transforms are the matrices `B^T`, `A^T`, `G` of Lavin and
/// Gray (2016) and the adjoints the weight gradient needs; the first three apply to values or
/// to vectors of them ([`Arith`]), the same operations in the same order either way.
pub(super) trait Minimal<const M: usize, const N: usize> {
    /// `B^T d`: a tile of inputs to its transformed values.
    fn input<A: Arith>(d: [A; N]) -> [A; N];
    /// `A^T m`: the products to the outputs.
    fn output<A: Arith>(m: [A; N]) -> [A; M];
    /// `A y`: output gradients to the products' gradients.
    fn output_adjoint<A: Arith>(y: [A; M]) -> [A; N];
    /// `G g`: 3 taps to `N` transformed weights.
    fn weight(g: [f64; 3]) -> [f64; N];
    /// `G^T u`: transformed weights' gradients back to the 3 taps.
    fn weight_adjoint(u: [f64; N]) -> [f64; 3];
}

/// `B^T` of `W`, F(M, 3), as a row map.
pub(super) struct Input<W, const M: usize, const N: usize>(PhantomData<W>);
/// `A^T` of `W`, F(M, 3), as a row map.
pub(super) struct Output<W, const M: usize, const N: usize>(PhantomData<W>);
/// `A` of `W`, F(M, 3), as a row map.
pub(super) struct OutputAdjoint<W, const M: usize, const N: usize>(PhantomData<W>);

/// Clone and Copy by hand: a derive would ask `W: Copy`.
macro_rules! transform_map {
    ($name:ident, $method:ident, $i:ident -> $o:ident) => {
        impl<W, const M: usize, const N: usize> Clone for $name<W, M, N> {
            fn clone(&self) -> Self {
                *self
            }
        }

        impl<W, const M: usize, const N: usize> Copy for $name<W, M, N> {}

        impl<W, const M: usize, const N: usize> $name<W, M, N> {
            /// The map of `W`.
            pub(super) fn of() -> Self {
                Self(PhantomData)
            }
        }

        impl<W: Minimal<M, N>, const M: usize, const N: usize> Map<$i, $o> for $name<W, M, N> {
            #[inline(always)]
            fn apply<A: Arith>(self, values: [A; $i]) -> [A; $o] {
                W::$method(values)
            }
        }
    };
}

transform_map!(Input, input, N -> N);
transform_map!(Output, output, N -> M);
transform_map!(OutputAdjoint, output_adjoint, M -> N);

/// F(2, 3), on the points 0, 1, -1 and infinity.
pub(super) struct F2;

impl Minimal<2, 4> for F2 {
    #[inline(always)]
    fn input<A: Arith>(d: [A; 4]) -> [A; 4] {
        [d[0] - d[2], d[1] + d[2], d[2] - d[1], d[1] - d[3]]
    }

    #[inline(always)]
    fn output<A: Arith>(m: [A; 4]) -> [A; 2] {
        [m[0] + m[1] + m[2], m[1] - m[2] - m[3]]
    }

    #[inline(always)]
    fn output_adjoint<A: Arith>(y: [A; 2]) -> [A; 4] {
        [y[0], y[0] + y[1], y[0] - y[1], y[1].zero() - y[1]]
    }

    fn weight(g: [f64; 3]) -> [f64; 4] {
        [
            g[0],
            (g[0] + g[1] + g[2]) / 2.0,
            (g[0] - g[1] + g[2]) / 2.0,
            g[2],
        ]
    }

    fn weight_adjoint(u: [f64; 4]) -> [f64; 3] {
        [
            u[0] + (u[1] + u[2]) / 2.0,
            (u[1] - u[2]) / 2.0,
            (u[1] + u[2]) / 2.0 + u[3],
        ]
    }
}

/// F(4, 3), on the points 0, 1, -1, 2, -2 and infinity.
pub(super) struct F4;

impl Minimal<4, 6> for F4 {
    #[inline(always)]
    fn input<A: Arith>(d: [A; 6]) -> [A; 6] {
        let (s12, d12) = (d[1] + d[2], d[1] - d[2]);
        let (s34, d34) = (d[4] + d[3], d[4] - d[3]);
        let (d42, d31) = (d[4] - d[2], d[3] - d[1]);
        [
            d[0].times(4.0) - d[2].times(5.0) + d[4],
            s34 - s12.times(4.0),
            d34 + d12.times(4.0),
            d42 + d31.times(2.0),
            d42 - d31.times(2.0),
            d[1].times(4.0) - d[3].times(5.0) + d[5],
        ]
    }

    #[inline(always)]
    fn output<A: Arith>(m: [A; 6]) -> [A; 4] {
        let (s12, d12) = (m[1] + m[2], m[1] - m[2]);
        let (s34, d34) = (m[3] + m[4], m[3] - m[4]);
        [
            m[0] + s12 + s34,
            d12 + d34.times(2.0),
            s12 + s34.times(4.0),
            d12 + d34.times(8.0) + m[5],
        ]
    }

    #[inline(always)]
    fn output_adjoint<A: Arith>(y: [A; 4]) -> [A; 6] {
        let (even1, odd1) = (y[0] + y[2], y[1] + y[3]);
        let (even2, odd2) = (y[0] + y[2].times(4.0), y[1].times(2.0) + y[3].times(8.0));
        [
            y[0],
            even1 + odd1,
            even1 - odd1,
            even2 + odd2,
            even2 - odd2,
            y[3],
        ]
    }

    fn weight(g: [f64; 3]) -> [f64; 6] {
        [
            g[0] / 4.0,
            -(g[0] + g[1] + g[2]) / 6.0,
            -(g[0] - g[1] + g[2]) / 6.0,
            (g[0] + 2.0 * g[1] + 4.0 * g[2]) / 24.0,
            (g[0] - 2.0 * g[1] + 4.0 * g[2]) / 24.0,
            g[2],
        ]
    }

    fn weight_adjoint(u: [f64; 6]) -> [f64; 3] {
        [
            u[0] / 4.0 - (u[1] + u[2]) / 6.0 + (u[3] + u[4]) / 24.0,
            (u[2] - u[1]) / 6.0 + (u[3] - u[4]) / 12.0,
            (u[3] + u[4] - u[1] - u[2]) / 6.0 + u[5],
        ]
    }
}

/// Applies a 1D map (`I` values to `O`) along `axis` of the row-major block `src` of `shape`
/// whose elements are rows of `width` values (one per channel pair), into `dst`; returns the
/// new shape.
fn along_axis<const I: usize, const O: usize>(
    src: &[f64],
    dst: &mut [f64],
    (shape, width): ([usize; 3], usize),
    axis: usize,
    map: impl Fn([f64; I]) -> [f64; O],
) -> [usize; 3] {
    let mut out_shape = shape;
    out_shape[axis] = O;
    let strides = [shape[1] * shape[2], shape[2], 1];
    let out_strides = [out_shape[1] * out_shape[2], out_shape[2], 1];
    let (a, b) = match axis {
        0 => (1, 2),
        1 => (0, 2),
        _ => (0, 1),
    };
    for i in 0..shape[a] {
        for j in 0..shape[b] {
            let base = i * strides[a] + j * strides[b];
            let out_base = i * out_strides[a] + j * out_strides[b];
            map_rows_with(
                (src, std::array::from_fn(|t| base + t * strides[axis])),
                (
                    dst,
                    std::array::from_fn(|t| out_base + t * out_strides[axis]),
                ),
                width,
                &map,
            );
        }
    }
    out_shape
}

/// The weights' transform (`G` or its adjoint) for a block of channel pairs: `map` along every
/// axis with 3 taps of `buf`, laid out `(tap or position, pair)` with `pairs` (the block's
/// width) per row and
/// `shape` the block of taps or positions, with `tmp` as the other buffer. Returns the buffer
/// holding the result. Vectorised across pairs: one tile at a time, this was 8% of the 28^3
/// generator step.
fn along_tap_axes<'a, const I: usize, const O: usize>(
    mut buf: &'a mut Vec<f64>,
    mut tmp: &'a mut Vec<f64>,
    (mut shape, pairs): ([usize; 3], usize),
    kernel: [usize; 3],
    map: impl Fn([f64; I]) -> [f64; O] + Copy,
) -> &'a [f64] {
    for (axis, &taps) in kernel.iter().enumerate() {
        if taps == 3 {
            let out_len = shape.iter().product::<usize>() / I * O * pairs;
            at_least(tmp, out_len);
            shape = along_axis(buf, tmp, (shape, pairs), axis, map);
            std::mem::swap(&mut buf, &mut tmp);
        }
    }
    &buf[..shape.iter().product::<usize>() * pairs]
}

/// Channel pairs a task of [`map_pair_blocks`] transforms: 64 pairs of 216 positions in f64
/// are 108 KiB, twice that with the other buffer, within a core's L2 cache.
const PAIR_BLOCK: usize = 64;

/// [`along_tap_axes`] for all `pairs` channel pairs, [`PAIR_BLOCK`] pairs per rayon task: the
/// weights' transforms ran on one thread while the other waited (4% of a 28^3 generator
/// step's samples, 7% of its wall time). `read(pairs, buf)` fills `buf` with the block's
/// values in `shape` laid out `(index, pair)`; `write(pairs, result)` takes the transformed
/// block, laid out the same way. Every pair is transformed on its own, so the split changes no
/// bits.
pub(super) fn map_pair_blocks<const I: usize, const O: usize>(
    pairs: usize,
    (shape, kernel): ([usize; 3], [usize; 3]),
    map: impl Fn([f64; I]) -> [f64; O] + Copy + Sync,
    read: impl Fn(Range<usize>, &mut [f64]) + Sync,
    write: impl Fn(Range<usize>, &[f64]) + Sync,
) {
    let values: usize = shape.iter().product();
    (0..pairs.div_ceil(PAIR_BLOCK))
        .into_par_iter()
        .for_each(|block| {
            // From the thread's pool: fresh buffers per task were allocated and zeroed again
            // for every call.
            let mut scratch = Pooled::<PairScratch>::take();
            let PairScratch { buf, tmp } = &mut *scratch;
            let range = block * PAIR_BLOCK..((block + 1) * PAIR_BLOCK).min(pairs);
            let width = range.len();
            at_least(buf, values * width);
            read(range.clone(), &mut buf[..values * width]);
            write(range, along_tap_axes(buf, tmp, (shape, width), kernel, map));
        });
}

/// The two buffers a task of [`map_pair_blocks`] transforms in, reused across calls.
#[derive(Default)]
struct PairScratch {
    buf: Vec<f64>,
    tmp: Vec<f64>,
}

/// The transformed weights `U[position][c_out][c_in]` of `w` `(C_out, C_in, kd, kh, kw)`.
pub(super) fn transform_weights<T: Element, W: Minimal<M, N>, const M: usize, const N: usize>(
    w: &[T],
    g: &Geometry,
) -> Vec<T> {
    let taps: usize = g.kernel.iter().product();
    let pairs = g.c_out * g.c_in;
    let positions: usize = g
        .kernel
        .map(|k| if k == 3 { N } else { 1 })
        .iter()
        .product();
    let mut u = unwritten::<T>(positions * pairs);
    let dst = SharedMut(u.as_mut_ptr());
    map_pair_blocks(
        pairs,
        (g.kernel, g.kernel),
        W::weight,
        |range, by_tap| {
            let width = range.len();
            for (j, pair) in range.enumerate() {
                for (t, v) in w[pair * taps..][..taps].iter().enumerate() {
                    by_tap[t * width + j] = v.to_f64();
                }
            }
        },
        |range, by_position| {
            let width = range.len();
            for (pos, values) in by_position.chunks_exact(width).enumerate() {
                for (j, v) in values.iter().enumerate() {
                    // SAFETY: `pos * pairs + range.start + j` < positions * pairs; the blocks'
                    // pair ranges are disjoint, so no two tasks write one value.
                    unsafe {
                        dst.ptr()
                            .add(pos * pairs + range.start + j)
                            .write(T::from_f64(*v))
                    };
                }
            }
        },
    );
    // SAFETY: every block wrote its pairs at every position, and the blocks cover all pairs.
    unsafe { u.set_len(positions * pairs) };
    u
}

//! The transforms of a chunk's tiles: input tiles by `B^T`, products back by `A^T`, output
//! gradients expanded by `A`, each over whole rows of the chunk's tiles.

use super::minimal::{Input, Minimal, Output, OutputAdjoint};
use super::rows::{map_d_then_h, RowKernels};
use super::{matrix_stride, Plan, RowBuffers};
use crate::element::Element;
use crate::geometry::Geometry;

/// Fills `v` (`positions x C_in x cols` of the chunk, [`Plan::row_cols`] per row of tiles) with
/// the chunk's input tiles transformed by `B^T`: per channel, the rows of voxels under the
/// chunk's tiles (zeros in the padding) are split into phases and transformed along D and H as
/// whole rows, then along W, every row of tiles at once.
#[inline(always)]
pub(super) fn fill_transformed_inputs<
    T: Element,
    W: Minimal<M, N>,
    const M: usize,
    const N: usize,
>(
    kernels: impl RowKernels,
    v: &mut [T],
    bufs: &mut RowBuffers<T>,
    x_n: &[T],
    g: &Geometry,
    plan: &Plan,
    (row0, rows): (usize, usize),
) {
    let [ad, ah, aw] = plan.axes;
    let in_vox: usize = g.input.iter().product();
    let (half, cols) = (plan.row_cols(), rows * plan.row_cols());
    let (width, ld) = (M * cols, matrix_stride(cols));
    for c in 0..g.c_in {
        let x_c = &x_n[c * in_vox..(c + 1) * in_vox];
        for r in 0..rows {
            let (td, th) = plan.row_tiles(row0 + r);
            for a in 0..ad.ins {
                let z = (td * ad.outs + a).wrapping_sub(ad.padding);
                for b in 0..ah.ins {
                    let y = (th * ah.outs + b).wrapping_sub(ah.padding);
                    let dst = &mut bufs.a[(a * ah.ins + b) * width + r * half..];
                    // Wrapped (negative) indices are huge, so one comparison covers both sides.
                    if z < ad.input && y < ah.input {
                        let src = &x_c[(z * ah.input + y) * aw.input..][..aw.input];
                        kernels.deinterleave::<T, M>(dst, (cols, half), src, aw.padding);
                    } else {
                        (0..M).for_each(|p| dst[p * cols..][..half].fill(T::ZERO));
                    }
                }
            }
        }
        let dims = ((ad.ins, ah.ins), (ad.taps, ah.taps));
        let (nd, nh) = map_d_then_h(kernels, bufs, dims, width, Input::<W, M, N>::of());
        // Read past the last row by F(2, 3)'s unused column: a stale value there could be a
        // non-finite one, which the weight gradient's zero output gradients would not cancel.
        bufs.a[nd * nh * width] = T::ZERO;
        for row in 0..nd * nh {
            let phases = &bufs.a[row * width..];
            // Input i of tile t is the padded row's voxel M t + i: phase i % M, index t + i / M.
            let srcs = std::array::from_fn(|i| &phases[(i % M) * cols + i / M..]);
            let at = std::array::from_fn(|xi| ((row * N + xi) * g.c_in + c) * ld);
            kernels.map_into(srcs, v, at, cols, Input::<W, M, N>::of());
        }
    }
}

/// The outputs of channel `c` of a chunk of `cols` columns: `A^T` along W from the products
/// `m` (`positions x C_out x cols`), then along H and D over whole rows. The result, in
/// `bufs.a`, is `outs_d x outs_h` rows of `M` phases of `cols` values.
#[inline(always)]
pub(super) fn transform_outputs<T: Element, W: Minimal<M, N>, const M: usize, const N: usize>(
    kernels: impl RowKernels,
    bufs: &mut RowBuffers<T>,
    m: &[T],
    (c, c_out): (usize, usize),
    plan: &Plan,
    cols: usize,
) {
    let [ad, ah, _] = plan.axes;
    let (width, ld) = (M * cols, matrix_stride(cols));
    for row in 0..ad.ins * ah.ins {
        let srcs = std::array::from_fn(|xi| &m[((row * N + xi) * c_out + c) * ld..]);
        let at = std::array::from_fn(|p| row * width + p * cols);
        kernels.map_into(srcs, &mut bufs.a, at, cols, Output::<W, M, N>::of());
    }
    let dims = ((ad.ins, ah.ins), (ad.taps, ah.taps));
    map_d_then_h(kernels, bufs, dims, width, Output::<W, M, N>::of());
}

/// The output gradient of channel `c` over a chunk's tiles expanded by `A` into `z`
/// (`positions x C_out x cols`): rows of `grad_out` (zeros past the output and in the unused
/// column, in phases) expanded along D and H, then along W.
#[inline(always)]
pub(super) fn expand_output_grads<T: Element, W: Minimal<M, N>, const M: usize, const N: usize>(
    kernels: impl RowKernels,
    z: &mut [T],
    bufs: &mut RowBuffers<T>,
    go_c: &[T],
    (c, c_out): (usize, usize),
    (g, plan): (&Geometry, &Plan),
    (row0, rows): (usize, usize),
) {
    let [ad, ah, _] = plan.axes;
    let out = g.output();
    let (half, cols) = (plan.row_cols(), rows * plan.row_cols());
    let (width, ld) = (M * cols, matrix_stride(cols));
    for r in 0..rows {
        let (td, th) = plan.row_tiles(row0 + r);
        for a in 0..ad.outs {
            for b in 0..ah.outs {
                let (zz, yy) = (td * ad.outs + a, th * ah.outs + b);
                let dst = &mut bufs.a[(a * ah.outs + b) * width + r * half..];
                if zz < out[0] && yy < out[1] {
                    let src = &go_c[(zz * out[1] + yy) * out[2]..][..out[2]];
                    kernels.deinterleave::<T, M>(dst, (cols, half), src, 0);
                } else {
                    (0..M).for_each(|p| dst[p * cols..][..half].fill(T::ZERO));
                }
            }
        }
    }
    let dims = ((ad.outs, ah.outs), (ad.taps, ah.taps));
    let (nd, nh) = map_d_then_h(kernels, bufs, dims, width, OutputAdjoint::<W, M, N>::of());
    for row in 0..nd * nh {
        let srcs = std::array::from_fn(|p| &bufs.a[row * width + p * cols..]);
        let at = std::array::from_fn(|xi| ((row * N + xi) * c_out + c) * ld);
        kernels.map_into(srcs, z, at, cols, OutputAdjoint::<W, M, N>::of());
    }
}

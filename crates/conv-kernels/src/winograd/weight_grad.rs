//! The weight gradient's pass over a convolution's chunks: input tiles transformed, output
//! gradients expanded, their products summed per position in a fixed split of the chunks, and
//! the sums mapped back to the taps.

use rayon::prelude::*;

use super::minimal::{map_pair_blocks, Minimal, F2, F4};
use super::products::weight_product;
use super::rows::{Blocks, RowKernels};
use super::tiles::{expand_output_grads, fill_transformed_inputs};
use super::{matrix_stride, scratch_for, Build, ForwardScratch, Plan, Tile, WEIGHT_GRAD_BLOCKS};
use crate::buffers::recycle;
use crate::element::Element;
use crate::geometry::Geometry;
use crate::isa::Isa;
use crate::output::{unwritten, SharedMut};

/// What every chunk of a weight-gradient pass reads.
struct WeightGradPass<'a, T> {
    x: &'a [T],
    grad_out: &'a [T],
    g: &'a Geometry,
    plan: &'a Plan,
    isa: Isa,
}

/// One chunk of a weight-gradient pass: transform its input tiles (into `scratch.v`) and its
/// output-gradient tiles (into `scratch.m`), and write their products per position to `du`
/// (`first`: the block's first chunk) or add them to it. `du` has room for `positions x C_out x
/// C_in` values.
#[inline(always)]
fn weight_grad_chunk<T: Element, W: Minimal<M, N>, const M: usize, const N: usize>(
    kernels: impl RowKernels,
    pass: &WeightGradPass<'_, T>,
    scratch: &mut ForwardScratch<T>,
    du: &mut Vec<T>,
    (n, row0, rows): (usize, usize, usize),
    first: bool,
) {
    let (g, plan) = (pass.g, pass.plan);
    let (p, ci, co) = (plan.positions, g.c_in, g.c_out);
    let in_vox: usize = g.input.iter().product();
    let out_vox: usize = g.output().iter().product();
    let ForwardScratch { v, m: z, vt, bufs } = scratch;
    let cols = rows * plan.row_cols();
    let ld = matrix_stride(cols);
    let x_n = &pass.x[n * ci * in_vox..];
    fill_transformed_inputs::<T, W, M, N>(kernels, v, bufs, x_n, g, plan, (row0, rows));
    for c in 0..co {
        let go_c = &pass.grad_out[(n * co + c) * out_vox..][..out_vox];
        let tiles = (row0, rows);
        expand_output_grads::<T, W, M, N>(kernels, z, bufs, go_c, (c, co), (g, plan), tiles);
    }
    // The capacity, not the length: `du` is unwritten until the first chunk's products.
    // The matrix products below write through this pointer: it must have room for them all.
    assert!(
        du.capacity() >= p * co * ci,
        "weight gradient: du too small"
    );
    let du = du.spare_capacity_mut().as_mut_ptr().cast::<T>();
    for pos in 0..p {
        // SAFETY: dU[pos] is co x ci, Z[pos] co x cols and V[pos] ci x cols (rows `ld` apart),
        // all in bounds (`du` has room for p x co x ci). The unused columns of Z are zeros, so
        // those of V add nothing; the padding to `ld` is not read. Without `first` the products
        // are added to values an earlier chunk wrote.
        unsafe {
            weight_product(
                pass.isa,
                (co, ci, cols, ld),
                (du.add(pos * co * ci), !first),
                z[pos * co * ld..].as_ptr(),
                v[pos * ci * ld..].as_ptr(),
                vt,
            )
        };
    }
}

/// [`weight_grad_chunk`] compiled for AVX2 and FMA (see `forward_chunk_avx2`).
///
/// # Safety
/// The CPU must have AVX2 and FMA.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn weight_grad_chunk_avx2<T: Element, W: Minimal<M, N>, const M: usize, const N: usize>(
    kernels: impl RowKernels,
    pass: &WeightGradPass<'_, T>,
    scratch: &mut ForwardScratch<T>,
    (du, first): (&mut Vec<T>, bool),
    chunk: (usize, usize, usize),
) {
    weight_grad_chunk::<T, W, M, N>(kernels, pass, scratch, du, chunk, first)
}

/// [`weight_grad_chunk`] in `build`.
#[inline(always)]
fn weight_grad_chunk_in<T: Element, W: Minimal<M, N>, const M: usize, const N: usize>(
    build: Build,
    pass: &WeightGradPass<'_, T>,
    scratch: &mut ForwardScratch<T>,
    (du, first): (&mut Vec<T>, bool),
    chunk: (usize, usize, usize),
) {
    match build {
        Build::Portable => weight_grad_chunk::<T, W, M, N>(Blocks, pass, scratch, du, chunk, first),
        // SAFETY: a `Build` names AVX2 only on a CPU with AVX2 and FMA (`Build::of`).
        #[cfg(target_arch = "x86_64")]
        Build::Avx2 => unsafe {
            weight_grad_chunk_avx2::<T, W, M, N>(Blocks, pass, scratch, (du, first), chunk)
        },
        // SAFETY: as above; AVX-512 implies AVX2 and FMA here (`Isa`).
        #[cfg(target_arch = "x86_64")]
        Build::Avx512(wide) => unsafe {
            weight_grad_chunk_avx2::<T, W, M, N>(wide, pass, scratch, (du, first), chunk)
        },
    }
}

/// [`super::grad_weight`] with the given tile.
pub(super) fn grad_weight_tiled<T: Element>(
    x: &[T],
    grad_out: &[T],
    g: &Geometry,
    tile: Tile,
) -> Vec<T> {
    match tile {
        Tile::F2 => grad_weight_with::<T, F2, 2, 4>(x, grad_out, g),
        Tile::F4 => grad_weight_with::<T, F4, 4, 6>(x, grad_out, g),
    }
}

/// [`super::grad_weight`] with F(M, 3).
fn grad_weight_with<T: Element, W: Minimal<M, N>, const M: usize, const N: usize>(
    x: &[T],
    grad_out: &[T],
    g: &Geometry,
) -> Vec<T> {
    let isa = Isa::current();
    let plan = Plan::new(g, M, isa);
    let (p, ci, co) = (plan.positions, g.c_in, g.c_out);
    let chunks = plan.chunks(g.batch);
    let per_block = chunks.len().div_ceil(WEIGHT_GRAD_BLOCKS).max(1);
    let pass = WeightGradPass {
        x,
        grad_out,
        g,
        plan: &plan,
        isa,
    };
    let build = Build::of(isa);
    let partials: Vec<Vec<T>> = chunks
        .par_chunks(per_block)
        .map(|block| {
            let mut du = unwritten::<T>(p * co * ci);
            let mut scratch = scratch_for(&plan, ci, co);
            for (i, &chunk) in block.iter().enumerate() {
                // The block's first chunk writes `du`, the others add to it.
                let first = i == 0;
                weight_grad_chunk_in::<T, W, M, N>(
                    build,
                    &pass,
                    &mut scratch,
                    (&mut du, first),
                    chunk,
                );
            }
            // SAFETY: the first chunk's products wrote every value of every position.
            unsafe { du.set_len(p * co * ci) };
            du
        })
        .collect();
    let taps: usize = g.kernel.iter().product();
    let pairs = co * ci;
    let mut dw = unwritten::<T>(pairs * taps);
    let dst = SharedMut(dw.as_mut_ptr());
    map_pair_blocks(
        pairs,
        (plan.axes.map(|a| a.ins), g.kernel),
        W::weight_adjoint,
        |range, sums| {
            // The partials' sum, in f64, in a fixed order per value: the same bits on any
            // number of threads.
            let width = range.len();
            sums.fill(0.0);
            for partial in &partials {
                for (pos, row) in sums.chunks_exact_mut(width).enumerate() {
                    let values = &partial[pos * pairs + range.start..][..width];
                    row.iter_mut()
                        .zip(values)
                        .for_each(|(a, b)| *a += b.to_f64());
                }
            }
        },
        |range, by_tap| {
            let width = range.len();
            for (t, values) in by_tap.chunks_exact(width).enumerate() {
                for (j, v) in values.iter().enumerate() {
                    // SAFETY: `(range.start + j) * taps + t` < pairs * taps; the blocks' pair
                    // ranges are disjoint, so no two tasks write one value.
                    unsafe {
                        dst.ptr()
                            .add((range.start + j) * taps + t)
                            .write(T::from_f64(*v))
                    };
                }
            }
        },
    );
    partials.into_iter().for_each(recycle);
    // SAFETY: every block wrote every tap of its pairs, and the blocks cover all pairs.
    unsafe { dw.set_len(pairs * taps) };
    dw
}

//! The forward pass over a convolution's chunks (also the input gradient's, on the transposed
//! convolution): input tiles transformed, multiplied by the transformed weights per position,
//! transformed back and written to the output rows under the chunk's tiles.

use rayon::prelude::*;

use super::minimal::{transform_weights, Minimal, F2, F4};
use super::products::forward_product;
use super::rows::{Blocks, RowKernels};
use super::tiles::{fill_transformed_inputs, transform_outputs};
use super::{matrix_stride, scratch_for, Build, ForwardScratch, Plan, Tile};
use crate::buffers::recycle;
use crate::element::Element;
use crate::geometry::Geometry;
use crate::isa::Isa;
use crate::output::{unwritten, SharedMut};

/// What every chunk of a forward pass reads.
struct ForwardPass<'a, T> {
    x: &'a [T],
    /// Transformed weights.
    u: &'a [T],
    g: &'a Geometry,
    plan: &'a Plan,
    y: SharedMut<T>,
    isa: Isa,
}

/// One chunk of a forward pass: transform its input tiles, multiply per position, transform
/// the products back and write the outputs.
#[inline(always)]
fn forward_chunk<T: Element, W: Minimal<M, N>, const M: usize, const N: usize>(
    kernels: impl RowKernels,
    pass: &ForwardPass<'_, T>,
    scratch: &mut ForwardScratch<T>,
    (n, row0, rows): (usize, usize, usize),
) {
    let (g, plan) = (pass.g, pass.plan);
    let (p, ci, co) = (plan.positions, g.c_in, g.c_out);
    let [ad, ah, _] = plan.axes;
    let in_vox: usize = g.input.iter().product();
    let out = g.output();
    let out_vox: usize = out.iter().product();
    let ForwardScratch { v, m, bufs, .. } = scratch;
    let (half, cols) = (plan.row_cols(), rows * plan.row_cols());
    let ld = matrix_stride(cols);
    let x_n = &pass.x[n * ci * in_vox..];
    fill_transformed_inputs::<T, W, M, N>(kernels, v, bufs, x_n, g, plan, (row0, rows));
    for pos in 0..p {
        // SAFETY: U[pos] is co x ci, V[pos] ci x ld, M[pos] co x ld, all in bounds.
        unsafe {
            forward_product(
                pass.isa,
                (co, ci, ld),
                m[pos * co * ld..].as_mut_ptr(),
                pass.u[pos * co * ci..].as_ptr(),
                v[pos * ci * ld..].as_ptr(),
            )
        };
    }
    let width = M * cols;
    for c in 0..co {
        transform_outputs::<T, W, M, N>(kernels, bufs, m, (c, co), plan, cols);
        for r in 0..rows {
            let (td, th) = plan.row_tiles(row0 + r);
            for a in 0..ad.outs {
                for b in 0..ah.outs {
                    let (z, yy) = (td * ad.outs + a, th * ah.outs + b);
                    if z >= ad.output || yy >= ah.output {
                        continue;
                    }
                    let phases = &bufs.a[(a * ah.outs + b) * width + r * half..];
                    let at = (n * co + c) * out_vox + (z * out[1] + yy) * out[2];
                    // SAFETY: in bounds of `y`; this output row belongs to this chunk's tiles
                    // only, and no other reference to it exists.
                    let row =
                        unsafe { std::slice::from_raw_parts_mut(pass.y.ptr().add(at), out[2]) };
                    kernels.interleave::<T, M>(row, phases, cols);
                }
            }
        }
    }
}

/// [`forward_chunk`] compiled for AVX2 and FMA: with [`Blocks`], the transforms in 8-wide
/// vectors; with the AVX-512 row kernels, the rest of the chunk's work.
///
/// # Safety
/// The CPU must have AVX2 and FMA.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn forward_chunk_avx2<T: Element, W: Minimal<M, N>, const M: usize, const N: usize>(
    kernels: impl RowKernels,
    pass: &ForwardPass<'_, T>,
    scratch: &mut ForwardScratch<T>,
    chunk: (usize, usize, usize),
) {
    forward_chunk::<T, W, M, N>(kernels, pass, scratch, chunk)
}

/// [`forward_chunk`] in `build`.
#[inline(always)]
fn forward_chunk_in<T: Element, W: Minimal<M, N>, const M: usize, const N: usize>(
    build: Build,
    pass: &ForwardPass<'_, T>,
    scratch: &mut ForwardScratch<T>,
    chunk: (usize, usize, usize),
) {
    match build {
        Build::Portable => forward_chunk::<T, W, M, N>(Blocks, pass, scratch, chunk),
        // SAFETY: a `Build` names AVX2 only on a CPU with AVX2 and FMA (`Build::of`).
        #[cfg(target_arch = "x86_64")]
        Build::Avx2 => unsafe { forward_chunk_avx2::<T, W, M, N>(Blocks, pass, scratch, chunk) },
        // SAFETY: as above; AVX-512 implies AVX2 and FMA here (`Isa`).
        #[cfg(target_arch = "x86_64")]
        Build::Avx512(wide) => unsafe {
            forward_chunk_avx2::<T, W, M, N>(wide, pass, scratch, chunk)
        },
    }
}

/// [`super::forward`] with the given tile.
pub(super) fn forward_tiled<T: Element>(x: &[T], w: &[T], g: &Geometry, tile: Tile) -> Vec<T> {
    match tile {
        Tile::F2 => forward_with::<T, F2, 2, 4>(x, w, g),
        Tile::F4 => forward_with::<T, F4, 4, 6>(x, w, g),
    }
}

/// [`super::forward`] with F(M, 3).
fn forward_with<T: Element, W: Minimal<M, N>, const M: usize, const N: usize>(
    x: &[T],
    w: &[T],
    g: &Geometry,
) -> Vec<T> {
    let isa = Isa::current();
    let plan = Plan::new(g, M, isa);
    let u = transform_weights::<T, W, M, N>(w, g);
    let out_vox: usize = g.output().iter().product();
    let mut y = unwritten::<T>(g.batch * g.c_out * out_vox);
    let pass = ForwardPass {
        x,
        u: &u,
        g,
        plan: &plan,
        y: SharedMut(y.as_mut_ptr()),
        isa,
    };
    let build = Build::of(isa);
    plan.chunks(g.batch).into_par_iter().for_each_init(
        || scratch_for(&plan, g.c_in, g.c_out),
        |scratch, chunk| forward_chunk_in::<T, W, M, N>(build, &pass, scratch, chunk),
    );
    recycle(u);
    // SAFETY: the chunks cover every row of tiles of every batch item, and a chunk writes every
    // output row under its tiles.
    unsafe { y.set_len(g.batch * g.c_out * out_vox) };
    y
}

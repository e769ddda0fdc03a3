//! Winograd's minimal filtering F(m, 3), m = 2 or 4, for stride-1 convolutions whose kernels are
//! 3 or 1 taps along each axis: the generators' 3x3x3 and the critics' 3x3 (a 1x3x3 here).
//!
//! Along an axis with 3 taps, `m` outputs `y = A^T [(G g) . (B^T d)]` come from a tile `d` of
//! `m + 2` inputs with `m + 2` products instead of `3 m`; an axis with 1 tap is left as it is. A
//! 3D tile is the product of its axes: with F(2, 3), 4x4x4 inputs give 2x2x2 outputs with 64
//! products per channel pair instead of 216 (3.4x fewer); with F(4, 3), 6x6x6 inputs give 4x4x4
//! outputs with 216 products instead of 1728 (8x fewer), and 3.4 transformed values per output
//! instead of 8. The products are, for each transformed position, one matrix product
//! `C_out x C_in` by `C_in x tiles` (plus one unused column per row of tiles, see
//! `Plan::row_cols`), which `products` runs at full speed (on a kernel of its own or `gemm`'s).
//! All three passes of a convolution use it:
//!
//! - forward: input tiles transformed by `B^T`, weights by `G`, products by `A^T`;
//! - input gradient: the forward pass of the transposed convolution (kernel flipped, channels
//!   swapped, padding `k - 1 - p`), as in the im2col kernel;
//! - weight gradient: the adjoint of the forward pass in `g`, `dg = G^T [sum over tiles of
//!   (A dy) . (B^T d)]`: output-gradient tiles expanded by `A`, multiplied with the transformed
//!   input tiles (`C_out x tiles` by `tiles x C_in`, per position), and the sum mapped back by `G^T`.
//!
//! F(2, 3) uses the points 0, 1, -1 (entries 0, ±1, ±1/2) and rounds about as well as the direct
//! sum; F(4, 3) adds ±2 (entries up to 8 and 1/24) and rounds worse, by the factor its tests
//! state. Work is split into chunks of rows of tiles of one batch item, each a few times the L2
//! cache in transformed inputs and products (streamed through once; see `chunk_target`).
//!
//! The 1D transforms and the weights' transform are in `minimal`, the row-wise maps and the
//! split of rows into phases in `rows`, the matrix products in `products`; this module tiles a
//! convolution and runs its passes.

use rayon::prelude::*;

use super::cpu::{Geometry, SharedMut};
use super::scratch::{at_least, Pooled};
use crate::element::Element;
use crate::output::unwritten;
use crate::simd::has_avx2;

mod minimal;
mod products;
mod rows;

use minimal::{map_pair_blocks, transform_weights, Minimal, F2, F4};
use products::{forward_product, weight_product};
use rows::{deinterleave, interleave, map_d_then_h, map_into};

/// Elements of the transformed inputs plus products a chunk aims at, with `gemm`'s products
/// (f32: 8 MiB, eight times a core's L2 cache on the AVX-512 machine it was measured on; the
/// matrices are streamed through once). Measured there, 2 threads, with an even number of equal
/// chunks (`Plan::new`): 2^21 as fast as 2^20 at 28^3 and 54^2, 2-5% faster from 40^3 (fewer,
/// longer products and transform loops); 2^18, 2^19 and 2^22 slower. With chunks of a fixed
/// row count instead, 2^21 had left 28^3 three chunks for two threads.
const CHUNK_TARGET_ELEMS: usize = 1 << 21;

/// [`CHUNK_TARGET_ELEMS`] on CPUs that run our own products (`products`, AVX2 without AVX-512):
/// 2 MiB of f32. Those read their right operand in place, a panel at a time, where `gemm` packs
/// it: a chunk whose matrices stay nearer the core pays. (The passes such CPUs still leave to
/// `gemm`, f64 and weight gradients of input channels not a multiple of 8, take it too,
/// unmeasured.) Measured on a Zen 3 machine (512 KiB of L2 per core), 2 threads, `gan_step`
/// medians of 3 alternated runs in two sets: the 108^2 critic 0.135-0.143 s at 2^21, 0.111 at
/// 2^20, 0.102-0.125 at 2^19, 0.119 at 2^18; 40^3 0.238-0.278 s at 2^21, 0.214 at 2^20,
/// 0.204-0.223 at 2^19, 0.260 at 2^18; 28^3 and the 54^2 critic 2-6% faster at 2^19.
const CHUNK_TARGET_ELEMS_OWN_PRODUCTS: usize = 1 << 19;

/// The chunk target of this CPU: the chunks, and so the weight gradient's partial sums, depend
/// on the instruction set as the products' roundings do, never on the thread count.
fn chunk_target() -> usize {
    if products::own_kernels() {
        CHUNK_TARGET_ELEMS_OWN_PRODUCTS
    } else {
        CHUNK_TARGET_ELEMS
    }
}

/// Row stride of the transformed matrices: a chunk's columns rounded up to 16. `gemm` multiplies
/// an operand whose rows are a whole number of its 16-lane vectors where it lies, and copies
/// (packs) any other first: with the padding, the forward products read the transformed
/// inputs in place and run no partial-width kernels (the padded columns' products are never
/// read). Measured, one thread, three runs alternated: a 40^3 generator step 2-3% faster, 28^3
/// and the 54^2 critic unchanged. Our own kernels (`products`) need a multiple of 8 only; the
/// same stride serves both.
fn matrix_stride(cols: usize) -> usize {
    cols.next_multiple_of(16)
}

/// Partial sums of the weight gradient, as in the im2col kernel: a fixed split of the chunks, so
/// the bits do not depend on thread scheduling.
const WEIGHT_GRAD_BLOCKS: usize = 8;

/// Whether the geometry has the shape F(m, 3) handles: stride 1, 3 taps along W and 1 or 3
/// along D and H, and padding at most `k - 1` (so the input gradient is a convolution too).
pub(crate) fn supports(g: &Geometry) -> bool {
    g.stride == 1
        && g.kernel[2] == 3
        && g.kernel.iter().all(|&k| k == 1 || k == 3)
        && (0..3).all(|a| g.padding[a] < g.kernel[a])
}

/// Which F(m, 3) a convolution uses along its 3-tap axes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Tile {
    F2,
    F4,
}

impl Tile {
    /// The tile for `g`: F(4, 3) once every 3-tap axis has at least 8 outputs (two tiles; below
    /// that the overhanging tile's work is too large a share), else F(2, 3).
    fn for_geometry(g: &Geometry) -> Self {
        let out = g.output();
        if (0..3).all(|a| g.kernel[a] == 1 || out[a] >= 8) {
            Tile::F4
        } else {
            Tile::F2
        }
    }
}

/// How one axis is tiled.
#[derive(Debug, Clone, Copy)]
struct Axis {
    /// Taps: 1 or 3.
    taps: usize,
    /// Outputs per tile: 1, or the tile's `m` for 3 taps.
    outs: usize,
    /// Inputs per tile (`outs + taps - 1`).
    ins: usize,
    /// Tiles along the axis.
    tiles: usize,
    input: usize,
    output: usize,
    padding: usize,
}

/// The tiling of one convolution. Tiles are taken a row at a time (the tiles along W of one
/// `(n, D tile, H tile)`), so the transforms along D and H run over whole rows of voxels.
#[derive(Debug, Clone)]
struct Plan {
    axes: [Axis; 3],
    /// Transformed tile size: the product of the axes' `ins`.
    positions: usize,
    /// Rows of tiles per batch item.
    rows: usize,
    /// Chunks per batch item.
    chunk_count: usize,
    /// Rows per chunk at most.
    chunk_rows: usize,
}

impl Plan {
    /// The tiling of `g` with `m` outputs per tile along its 3-tap axes (F(m, 3)).
    fn new(g: &Geometry, m: usize) -> Self {
        let out = g.output();
        let axes = [0, 1, 2].map(|a| {
            let taps = g.kernel[a];
            let outs = if taps == 3 { m } else { 1 };
            Axis {
                taps,
                outs,
                ins: outs + taps - 1,
                tiles: out[a].div_ceil(outs),
                input: g.input[a],
                output: out[a],
                padding: g.padding[a],
            }
        });
        let positions: usize = axes.iter().map(|a| a.ins).product();
        let per_row = positions * (g.c_in + g.c_out) * (axes[2].tiles + 1);
        let rows = axes[0].tiles * axes[1].tiles;
        let most = (chunk_target() / per_row).clamp(1, rows);
        // An even number of chunks of nearly equal rows (sizes at most one row apart), so
        // that two threads get equal shares: 28^3's 49 rows in chunks of 9 left the last
        // chunk 4 rows and one thread 27 rows against 22. Fixed by the geometry alone, not the
        // threads, so the weight gradient's sums keep their bits on any number of threads.
        let mut chunk_count = rows.div_ceil(most);
        if chunk_count % 2 == 1 && chunk_count > 1 && chunk_count < rows {
            chunk_count += 1;
        }
        Self {
            axes,
            positions,
            rows,
            chunk_count,
            chunk_rows: rows.div_ceil(chunk_count),
        }
    }

    /// Columns per row of tiles in the transformed matrices: the row's tiles and one more, whose
    /// values no output reads. With it the phases of a row (below) and the matrices' rows have
    /// one stride, so the transforms of a chunk run over all its rows at once instead of a few
    /// tiles at a time (7 at 28^3, where short loops and scattered stores were most of a pass).
    fn row_cols(&self) -> usize {
        self.axes[2].tiles + 1
    }

    /// Columns of a chunk's transformed matrices at most.
    fn chunk_cols(&self) -> usize {
        self.chunk_rows * self.row_cols()
    }

    /// Work items: `(batch item, first row, rows)`.
    fn chunks(&self, batch: usize) -> Vec<(usize, usize, usize)> {
        (0..batch)
            .flat_map(|n| {
                let start = |i: usize| i * self.rows / self.chunk_count;
                (0..self.chunk_count).map(move |i| (n, start(i), start(i + 1) - start(i)))
            })
            .collect()
    }

    /// The `(D, H)` tile indices of a row.
    fn row_tiles(&self, row: usize) -> (usize, usize) {
        (row / self.axes[1].tiles, row % self.axes[1].tiles)
    }
}

/// Per-task buffers of a chunk's rows of voxels, reused across chunks. A row holds, for one
/// `(D, H)` offset in the tiles, the voxels along W of every row of tiles of the chunk, split
/// into `M` phases of [`Plan::row_cols`] values per row of tiles: phase `p` holds the voxels
/// `M k + p`, so that the W transform, whose tiles step by `M`, reads every operand with unit
/// stride and vectorises.
struct RowBuffers<T> {
    a: Vec<T>,
    b: Vec<T>,
}

impl<T: Element> RowBuffers<T> {
    /// Length of each of the two buffers for `plan`: one value past the rows, which the W
    /// transform of F(2, 3) reads for the unused column of the last row.
    fn len(plan: &Plan) -> usize {
        let [ad, ah, aw] = plan.axes;
        ad.ins * ah.ins * aw.outs * plan.chunk_cols() + 1
    }
}

/// Fills `v` (`positions x C_in x cols` of the chunk, [`Plan::row_cols`] per row of tiles) with
/// the chunk's input tiles transformed by `B^T`: per channel, the rows of voxels under the
/// chunk's tiles (zeros in the padding) are split into phases and transformed along D and H as
/// whole rows, then along W, every row of tiles at once.
#[inline(always)]
fn fill_transformed_inputs<T: Element, W: Minimal<M, N>, const M: usize, const N: usize>(
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
                        deinterleave::<T, M>(dst, (cols, half), src, aw.padding);
                    } else {
                        (0..M).for_each(|p| dst[p * cols..][..half].fill(T::ZERO));
                    }
                }
            }
        }
        let (nd, nh) = map_d_then_h(bufs, (ad.ins, ah.ins), (ad.taps, ah.taps), width, W::input);
        // Read past the last row by F(2, 3)'s unused column: a stale value there could be a
        // non-finite one, which the weight gradient's zero output gradients would not cancel.
        bufs.a[nd * nh * width] = T::ZERO;
        for row in 0..nd * nh {
            let phases = &bufs.a[row * width..];
            // Input i of tile t is the padded row's voxel M t + i: phase i % M, index t + i / M.
            let srcs = std::array::from_fn(|i| &phases[(i % M) * cols + i / M..]);
            let at = std::array::from_fn(|xi| ((row * N + xi) * g.c_in + c) * ld);
            map_into(srcs, v, at, cols, W::input);
        }
    }
}

/// The outputs of channel `c` of a chunk of `cols` columns: `A^T` along W from the products
/// `m` (`positions x C_out x cols`), then along H and D over whole rows. The result, in
/// `bufs.a`, is `outs_d x outs_h` rows of `M` phases of `cols` values.
#[inline(always)]
fn transform_outputs<T: Element, W: Minimal<M, N>, const M: usize, const N: usize>(
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
        map_into(srcs, &mut bufs.a, at, cols, W::output);
    }
    map_d_then_h(bufs, (ad.ins, ah.ins), (ad.taps, ah.taps), width, W::output);
}

/// The output gradient of channel `c` over a chunk's tiles expanded by `A` into `z`
/// (`positions x C_out x cols`): rows of `grad_out` (zeros past the output and in the unused
/// column, in phases) expanded along D and H, then along W.
#[inline(always)]
fn expand_output_grads<T: Element, W: Minimal<M, N>, const M: usize, const N: usize>(
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
                    deinterleave::<T, M>(dst, (cols, half), src, 0);
                } else {
                    (0..M).for_each(|p| dst[p * cols..][..half].fill(T::ZERO));
                }
            }
        }
    }
    let (nd, nh) = map_d_then_h(
        bufs,
        (ad.outs, ah.outs),
        (ad.taps, ah.taps),
        width,
        W::output_adjoint,
    );
    for row in 0..nd * nh {
        let srcs = std::array::from_fn(|p| &bufs.a[row * width + p * cols..]);
        let at = std::array::from_fn(|xi| ((row * N + xi) * c_out + c) * ld);
        map_into(srcs, z, at, cols, W::output_adjoint);
    }
}

/// What every chunk of a forward pass reads.
struct ForwardPass<'a, T> {
    x: &'a [T],
    /// Transformed weights.
    u: &'a [T],
    g: &'a Geometry,
    plan: &'a Plan,
    y: SharedMut<T>,
}

/// The per-task scratch of a pass: transformed inputs, products (or transformed output
/// gradients), rows. Every chunk writes each value it reads first, but for the padding of the
/// matrices' rows ([`matrix_stride`]), whose products are never read; so a scratch is reused
/// from the thread's pool as it is ([`scratch_for`]).
struct ForwardScratch<T> {
    v: Vec<T>,
    m: Vec<T>,
    /// A position's `V^T`, for the weight gradient's products (grown as they need it).
    vt: Vec<T>,
    bufs: RowBuffers<T>,
}

// By hand: a derive would ask `T: Default`.
impl<T> Default for ForwardScratch<T> {
    fn default() -> Self {
        Self {
            v: Vec::new(),
            m: Vec::new(),
            vt: Vec::new(),
            bufs: RowBuffers {
                a: Vec::new(),
                b: Vec::new(),
            },
        }
    }
}

/// A pooled [`ForwardScratch`] large enough for a pass of `plan`.
fn scratch_for<T: Element>(plan: &Plan, c_in: usize, c_out: usize) -> Pooled<ForwardScratch<T>> {
    let (p, most) = (plan.positions, matrix_stride(plan.chunk_cols()));
    let mut scratch = Pooled::<ForwardScratch<T>>::take();
    let rows = RowBuffers::<T>::len(plan);
    let ForwardScratch { v, m, bufs, .. } = &mut *scratch;
    at_least(v, p * c_in * most);
    at_least(m, p * c_out * most);
    at_least(&mut bufs.a, rows);
    at_least(&mut bufs.b, rows);
    scratch
}

/// One chunk of a forward pass: transform its input tiles, multiply per position, transform
/// the products back and write the outputs.
#[inline(always)]
fn forward_chunk<T: Element, W: Minimal<M, N>, const M: usize, const N: usize>(
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
    fill_transformed_inputs::<T, W, M, N>(v, bufs, x_n, g, plan, (row0, rows));
    for pos in 0..p {
        // SAFETY: U[pos] is co x ci, V[pos] ci x ld, M[pos] co x ld, all in bounds.
        unsafe {
            forward_product(
                (co, ci, ld),
                m[pos * co * ld..].as_mut_ptr(),
                pass.u[pos * co * ci..].as_ptr(),
                v[pos * ci * ld..].as_ptr(),
            )
        };
    }
    let width = M * cols;
    for c in 0..co {
        transform_outputs::<T, W, M, N>(bufs, m, (c, co), plan, cols);
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
                    interleave::<T, M>(row, phases, cols);
                }
            }
        }
    }
}

/// [`forward_chunk`] compiled for AVX2, whose 8-wide vectors the transforms use.
///
/// # Safety
/// The CPU must have AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn forward_chunk_avx2<T: Element, W: Minimal<M, N>, const M: usize, const N: usize>(
    pass: &ForwardPass<'_, T>,
    scratch: &mut ForwardScratch<T>,
    chunk: (usize, usize, usize),
) {
    forward_chunk::<T, W, M, N>(pass, scratch, chunk)
}

/// `y = conv3d(x, w)` without bias, as [`super::cpu::forward`], for a geometry [`supports`] accepts.
pub(crate) fn forward<T: Element>(x: &[T], w: &[T], g: &Geometry) -> Vec<T> {
    forward_tiled(x, w, g, Tile::for_geometry(g))
}

/// [`forward`] with the given tile.
fn forward_tiled<T: Element>(x: &[T], w: &[T], g: &Geometry, tile: Tile) -> Vec<T> {
    match tile {
        Tile::F2 => forward_with::<T, F2, 2, 4>(x, w, g),
        Tile::F4 => forward_with::<T, F4, 4, 6>(x, w, g),
    }
}

/// [`forward`] with F(M, 3).
fn forward_with<T: Element, W: Minimal<M, N>, const M: usize, const N: usize>(
    x: &[T],
    w: &[T],
    g: &Geometry,
) -> Vec<T> {
    let plan = Plan::new(g, M);
    let u = transform_weights::<T, W, M, N>(w, g);
    let out_vox: usize = g.output().iter().product();
    let mut y = unwritten::<T>(g.batch * g.c_out * out_vox);
    let pass = ForwardPass {
        x,
        u: &u,
        g,
        plan: &plan,
        y: SharedMut(y.as_mut_ptr()),
    };
    let avx2 = has_avx2();
    let _ = avx2; // read by the x86-64 branch only
    plan.chunks(g.batch).into_par_iter().for_each_init(
        || scratch_for(&plan, g.c_in, g.c_out),
        |scratch, chunk| {
            let scratch: &mut ForwardScratch<T> = scratch;
            #[cfg(target_arch = "x86_64")]
            if avx2 {
                // SAFETY: the CPU has AVX2 (checked above).
                return unsafe { forward_chunk_avx2::<T, W, M, N>(&pass, scratch, chunk) };
            }
            forward_chunk::<T, W, M, N>(&pass, scratch, chunk)
        },
    );
    // SAFETY: the chunks cover every row of tiles of every batch item, and a chunk writes every
    // output row under its tiles.
    unsafe { y.set_len(g.batch * g.c_out * out_vox) };
    y
}

/// Gradient of `sum(grad_out * conv3d(x, w))` with respect to `x`, as
/// [`super::cpu::grad_input`]: the forward pass of the transposed convolution.
pub(crate) fn grad_input<T: Element>(grad_out: &[T], w: &[T], g: &Geometry) -> Vec<T> {
    // `supports` admits only geometries that have one; the im2col kernel handles any other.
    let Some(transposed) = g.transposed() else {
        return super::cpu::grad_input(grad_out, w, g);
    };
    forward(grad_out, &super::cpu::flipped_transposed(w, g), &transposed)
}

/// What every chunk of a weight-gradient pass reads.
struct WeightGradPass<'a, T> {
    x: &'a [T],
    grad_out: &'a [T],
    g: &'a Geometry,
    plan: &'a Plan,
}

/// One chunk of a weight-gradient pass: transform its input tiles (into `scratch.v`) and its
/// output-gradient tiles (into `scratch.m`), and write their products per position to `du`
/// (`first`: the block's first chunk) or add them to it. `du` has room for `positions x C_out x
/// C_in` values.
#[inline(always)]
fn weight_grad_chunk<T: Element, W: Minimal<M, N>, const M: usize, const N: usize>(
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
    fill_transformed_inputs::<T, W, M, N>(v, bufs, x_n, g, plan, (row0, rows));
    for c in 0..co {
        let go_c = &pass.grad_out[(n * co + c) * out_vox..][..out_vox];
        expand_output_grads::<T, W, M, N>(z, bufs, go_c, (c, co), (g, plan), (row0, rows));
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
                (co, ci, cols, ld),
                (du.add(pos * co * ci), !first),
                z[pos * co * ld..].as_ptr(),
                v[pos * ci * ld..].as_ptr(),
                vt,
            )
        };
    }
}

/// [`weight_grad_chunk`] compiled for AVX2.
///
/// # Safety
/// The CPU must have AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn weight_grad_chunk_avx2<T: Element, W: Minimal<M, N>, const M: usize, const N: usize>(
    pass: &WeightGradPass<'_, T>,
    scratch: &mut ForwardScratch<T>,
    du: &mut Vec<T>,
    chunk: (usize, usize, usize),
    first: bool,
) {
    weight_grad_chunk::<T, W, M, N>(pass, scratch, du, chunk, first)
}

/// Gradient of `sum(grad_out * conv3d(x, w))` with respect to `w`, as
/// [`super::cpu::grad_weight`].
pub(crate) fn grad_weight<T: Element>(x: &[T], grad_out: &[T], g: &Geometry) -> Vec<T> {
    grad_weight_tiled(x, grad_out, g, Tile::for_geometry(g))
}

/// [`grad_weight`] with the given tile.
fn grad_weight_tiled<T: Element>(x: &[T], grad_out: &[T], g: &Geometry, tile: Tile) -> Vec<T> {
    match tile {
        Tile::F2 => grad_weight_with::<T, F2, 2, 4>(x, grad_out, g),
        Tile::F4 => grad_weight_with::<T, F4, 4, 6>(x, grad_out, g),
    }
}

/// [`grad_weight`] with F(M, 3).
fn grad_weight_with<T: Element, W: Minimal<M, N>, const M: usize, const N: usize>(
    x: &[T],
    grad_out: &[T],
    g: &Geometry,
) -> Vec<T> {
    let plan = Plan::new(g, M);
    let (p, ci, co) = (plan.positions, g.c_in, g.c_out);
    let chunks = plan.chunks(g.batch);
    let per_block = chunks.len().div_ceil(WEIGHT_GRAD_BLOCKS).max(1);
    let pass = WeightGradPass {
        x,
        grad_out,
        g,
        plan: &plan,
    };
    let avx2 = has_avx2();
    let _ = avx2; // read by the x86-64 branch only
    let partials: Vec<Vec<T>> = chunks
        .par_chunks(per_block)
        .map(|block| {
            let mut du = unwritten::<T>(p * co * ci);
            let mut scratch = scratch_for(&plan, ci, co);
            for (i, &chunk) in block.iter().enumerate() {
                // The block's first chunk writes `du`, the others add to it.
                let first = i == 0;
                #[cfg(target_arch = "x86_64")]
                if avx2 {
                    // SAFETY: the CPU has AVX2 (checked above).
                    unsafe {
                        weight_grad_chunk_avx2::<T, W, M, N>(
                            &pass,
                            &mut scratch,
                            &mut du,
                            chunk,
                            first,
                        )
                    };
                    continue;
                }
                weight_grad_chunk::<T, W, M, N>(&pass, &mut scratch, &mut du, chunk, first);
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
    // SAFETY: every block wrote every tap of its pairs, and the blocks cover all pairs.
    unsafe { dw.set_len(pairs * taps) };
    dw
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::conv::cpu;

    /// Deterministic values in [-1, 1).
    pub(super) fn values(n: usize, seed: u64) -> Vec<f64> {
        let mut s = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (0..n)
            .map(|_| {
                s = s
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                (s >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
            })
            .collect()
    }

    fn max_rel_diff(a: &[f64], b: &[f64]) -> f64 {
        assert_eq!(a.len(), b.len());
        let scale = b.iter().fold(1e-30f64, |m, v| m.max(v.abs()));
        a.iter().zip(b).fold(0f64, |m, (x, y)| m.max((x - y).abs())) / scale
    }

    fn geometries() -> Vec<Geometry> {
        let mut out = Vec::new();
        for (kernel, padding) in [
            ([3, 3, 3], [1, 1, 1]),
            ([3, 3, 3], [0, 0, 0]),
            ([1, 3, 3], [0, 0, 0]),
            ([1, 3, 3], [0, 1, 1]),
            ([3, 1, 3], [2, 0, 1]),
        ] {
            // Rows of 37 voxels take the (de)interleaving's blocks of 8 tiles with both tiles,
            // rows of 29 its blocks of 4 (F(2, 3) after a block of 8), the others only its
            // single tiles.
            for input in [[5, 6, 7], [4, 4, 4], [3, 8, 5], [4, 3, 37], [3, 4, 29]] {
                let input = [0, 1, 2].map(|a| {
                    if kernel[a] == 1 {
                        input[a].min(2)
                    } else {
                        input[a]
                    }
                });
                out.push(Geometry {
                    batch: 2,
                    c_in: 3,
                    c_out: 5,
                    input,
                    kernel,
                    padding,
                    stride: 1,
                });
            }
        }
        out
    }

    /// The three passes with `tile`; the input gradient as [`grad_input`] computes it.
    fn passes<T: Element>(x: &[T], w: &[T], go: &[T], g: &Geometry, tile: Tile) -> [Vec<T>; 3] {
        let transposed = g.transposed().unwrap();
        let flipped = cpu::flipped_transposed(w, g);
        [
            forward_tiled(x, w, g, tile),
            forward_tiled(go, &flipped, &transposed, tile),
            grad_weight_tiled(x, go, g, tile),
        ]
    }

    /// Asserts that the three passes with `tile` equal the im2col kernel's to 1e-13 relative on
    /// values drawn from `seed`.
    fn assert_passes_match_im2col(g: &Geometry, tile: Tile, seed: u64) {
        let in_len = g.batch * g.c_in * g.input.iter().product::<usize>();
        let out_len = g.batch * g.c_out * g.output().iter().product::<usize>();
        let w_len = g.c_out * g.c_in * g.kernel.iter().product::<usize>();
        let x = values(in_len, 3 * seed);
        let w = values(w_len, 3 * seed + 1);
        let go = values(out_len, 3 * seed + 2);
        let references = [
            cpu::forward(&x, &w, g),
            cpu::grad_input(&go, &w, g),
            cpu::grad_weight(&x, &go, g),
        ];
        let ours = passes(&x, &w, &go, g, tile);
        for (pass, (ours, reference)) in ours.iter().zip(&references).enumerate() {
            let err = max_rel_diff(ours, reference);
            assert!(
                err < 1e-13,
                "{tile:?} {g:?} pass {pass}: relative error {err}"
            );
        }
    }

    #[test]
    fn all_three_passes_match_the_im2col_kernel_in_f64() {
        for tile in [Tile::F2, Tile::F4] {
            for (i, g) in geometries().into_iter().enumerate() {
                assert!(supports(&g), "{g:?}");
                assert_passes_match_im2col(&g, tile, i as u64);
            }
        }
    }

    #[test]
    fn passes_split_into_several_chunks_match_im2col() {
        // 256 rows of tiles per batch item, 3 -> 5 channels: with `gemm`'s chunk target at most
        // 110 rows a chunk, so three chunks, made four (an even number) of 64 rows; with our
        // own products' a quarter of that, so ten of 25 or 26 rows.
        let g = Geometry {
            input: [62, 61, 37],
            ..geometries()[0]
        };
        let plan = Plan::new(&g, 4);
        let rows: Vec<usize> = plan.chunks(1).iter().map(|&(_, _, rows)| rows).collect();
        let expected = if chunk_target() == CHUNK_TARGET_ELEMS {
            vec![64; 4]
        } else {
            (0..10).map(|i| (i + 1) * 256 / 10 - i * 256 / 10).collect()
        };
        assert_eq!(rows, expected, "{plan:?}");
        assert_passes_match_im2col(&g, Tile::F4, 14);
    }

    #[test]
    fn weight_gradient_blocks_of_several_chunks_match_im2col() {
        // One chunk per batch item, more chunks than partial sums: a block's first chunk
        // writes its partial sum, the next adds to it.
        let g = Geometry {
            batch: WEIGHT_GRAD_BLOCKS + 1,
            ..geometries()[0]
        };
        let plan = Plan::new(&g, 2);
        assert_eq!(plan.chunks(1).len(), 1, "{plan:?}");
        assert_passes_match_im2col(&g, Tile::F2, 15);
    }

    #[test]
    fn the_public_passes_pick_f4_from_eight_outputs_and_match_im2col() {
        let mut g = geometries()[0];
        g.input = [9, 8, 12];
        assert_eq!(Tile::for_geometry(&g), Tile::F4);
        let small = Geometry {
            input: [7, 8, 12],
            ..g
        };
        assert_eq!(Tile::for_geometry(&small), Tile::F2);
        let x = values(g.batch * g.c_in * 9 * 8 * 12, 1);
        let w = values(g.c_out * g.c_in * 27, 2);
        let go = values(g.batch * g.c_out * 9 * 8 * 12, 3);
        let pairs = [
            (forward(&x, &w, &g), cpu::forward(&x, &w, &g)),
            (grad_input(&go, &w, &g), cpu::grad_input(&go, &w, &g)),
            (grad_weight(&x, &go, &g), cpu::grad_weight(&x, &go, &g)),
        ];
        for (pass, (ours, reference)) in pairs.iter().enumerate() {
            let err = max_rel_diff(ours, reference);
            assert!(err < 1e-13, "pass {pass}: relative error {err}");
        }
    }

    #[test]
    fn f32_rounding_stays_near_the_direct_sums_level() {
        let g = Geometry {
            batch: 1,
            c_in: 32,
            c_out: 32,
            input: [9, 10, 11],
            kernel: [3, 3, 3],
            padding: [1, 1, 1],
            stride: 1,
        };
        let vox = 990;
        let x = values(32 * vox, 7);
        let w: Vec<f64> = values(32 * 32 * 27, 8).iter().map(|v| v * 0.05).collect();
        let go = values(32 * vox, 9);
        let exact = [
            cpu::forward(&x, &w, &g),
            cpu::grad_input(&go, &w, &g),
            cpu::grad_weight(&x, &go, &g),
        ];
        let as_f32 = |v: &[f64]| v.iter().map(|&x| x as f32).collect::<Vec<f32>>();
        let widen = |v: &[f32]| v.iter().map(|&x| f64::from(x)).collect::<Vec<f64>>();
        let (x, w, go) = (as_f32(&x), as_f32(&w), as_f32(&go));
        let direct = [
            cpu::forward(&x, &w, &g),
            cpu::grad_input(&go, &w, &g),
            cpu::grad_weight(&x, &go, &g),
        ];
        // F(2, 3) rounds like the direct sums; F(4, 3)'s larger entries cost a bounded factor
        // (measured: 15x the im2col kernel's error forward and for the input gradient, 27x for
        // the weight gradient, whose im2col sums are unusually exact; all below 2e-5 relative).
        for (tile, factor) in [(Tile::F2, 4.0), (Tile::F4, 40.0)] {
            let ours = passes(&x, &w, &go, &g, tile);
            for pass in 0..3 {
                let ours_err = max_rel_diff(&widen(&ours[pass]), &exact[pass]);
                let direct_err = max_rel_diff(&widen(&direct[pass]), &exact[pass]);
                assert!(
                    ours_err < factor * direct_err.max(1e-7),
                    "{tile:?} pass {pass}: {ours_err} vs im2col {direct_err}"
                );
            }
        }
    }

    #[test]
    fn unsupported_geometries_are_left_to_im2col() {
        let base = geometries()[0];
        assert!(!supports(&Geometry { stride: 2, ..base }));
        assert!(!supports(&Geometry {
            kernel: [5, 5, 5],
            ..base
        }));
        assert!(!supports(&Geometry {
            kernel: [1, 1, 1],
            padding: [0; 3],
            ..base
        }));
        assert!(!supports(&Geometry {
            padding: [3, 1, 1],
            ..base
        }));
    }
}

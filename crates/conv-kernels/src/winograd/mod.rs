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
//! split of rows into phases in `rows`, the matrix products in `products`, the transforms of a
//! chunk's tiles in `tiles`, and the passes over a convolution's chunks in `forward` and
//! `weight_grad`; this module tiles a convolution (`Plan`) and holds the passes' entry points.

use crate::element::Element;
use crate::geometry::{assert_valid, Geometry};
use crate::im2col;
use crate::isa::Isa;
use crate::scratch::{at_least, Pooled};

#[cfg(target_arch = "x86_64")]
mod avx512;
mod forward;
mod minimal;
mod products;
mod rows;
#[cfg(test)]
mod tests;
mod tiles;
mod weight_grad;

use forward::forward_tiled;
use weight_grad::grad_weight_tiled;

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

/// The chunk target of a pass on `isa`: the chunks, and so the weight gradient's partial sums,
/// depend on the instruction set as the products' roundings do, never on the thread count.
fn chunk_target(isa: Isa) -> usize {
    if products::own_kernels(isa) {
        CHUNK_TARGET_ELEMS_OWN_PRODUCTS
    } else {
        CHUNK_TARGET_ELEMS
    }
}

/// The build a pass's chunks run in, from the pass's instruction set: the transforms in
/// baseline blocks, in AVX2 blocks, or in the 16-lane AVX-512 row kernels (the rest of the
/// chunk in the AVX2 build).
#[derive(Debug, Clone, Copy)]
enum Build {
    Portable,
    #[cfg(target_arch = "x86_64")]
    Avx2,
    #[cfg(target_arch = "x86_64")]
    Avx512(avx512::Avx512),
}

impl Build {
    /// The build of `isa`: AVX2 only where the CPU has AVX2 and FMA (an [`Isa`] is never above
    /// the CPU's), AVX-512 only where it has AVX-512 F too.
    fn of(isa: Isa) -> Self {
        match isa {
            Isa::Portable => Build::Portable,
            #[cfg(target_arch = "x86_64")]
            Isa::Avx2 => Build::Avx2,
            #[cfg(target_arch = "x86_64")]
            Isa::Avx512 => avx512::Avx512::new().map_or(Build::Avx2, Build::Avx512),
            #[cfg(not(target_arch = "x86_64"))]
            _ => Build::Portable,
        }
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
pub fn supports(g: &Geometry) -> bool {
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
    /// The tiling of `g` with `m` outputs per tile along its 3-tap axes (F(m, 3)), for a pass on
    /// `isa`.
    fn new(g: &Geometry, m: usize, isa: Isa) -> Self {
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
        let most = (chunk_target(isa) / per_row).clamp(1, rows);
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

/// Panics unless `g` is [valid](Geometry::is_valid), [supported](supports), and `a`, `b` are
/// `(what, length, expected length)` of the slices a pass was given.
#[track_caller]
fn assert_runs(g: &Geometry, a: (&str, usize, usize), b: (&str, usize, usize)) {
    assert!(supports(g), "conv-kernels: Winograd does not run {g:?}");
    assert_valid(g, [a, b]);
}

/// `y = conv3d(x, w)` without bias, as [`im2col::forward`], for a geometry [`supports`] accepts:
/// `x` `(N, C_in, D, H, W)`, `w` `(C_out, C_in, kd, kh, kw)`, `y` `(N, C_out, D_out, H_out,
/// W_out)`. F(4, 3) once every 3-tap axis has at least 8 outputs, else F(2, 3).
///
/// # Panics
/// Unless `g` is [valid](Geometry::is_valid) and [supported](supports) and the slices have its
/// lengths.
pub fn forward<T: Element>(x: &[T], w: &[T], g: &Geometry) -> Vec<T> {
    assert_runs(
        g,
        ("input", x.len(), g.input_len()),
        ("kernel", w.len(), g.kernel_len()),
    );
    forward_tiled(x, w, g, Tile::for_geometry(g))
}

/// Gradient of `sum(grad_out * conv3d(x, w))` with respect to `x`, as [`im2col::grad_input`]:
/// the forward pass of the transposed convolution.
///
/// # Panics
/// As [`forward`], with `grad_out` of the output's length.
pub fn grad_input<T: Element>(grad_out: &[T], w: &[T], g: &Geometry) -> Vec<T> {
    assert_runs(
        g,
        ("output gradient", grad_out.len(), g.output_len()),
        ("kernel", w.len(), g.kernel_len()),
    );
    // `supports` admits only geometries that have one; the im2col kernel handles any other.
    let Some(transposed) = g.transposed() else {
        return im2col::grad_input(grad_out, w, g);
    };
    forward(grad_out, &im2col::flipped_transposed(w, g), &transposed)
}

/// Gradient of `sum(grad_out * conv3d(x, w))` with respect to `w`, as [`im2col::grad_weight`].
///
/// # Panics
/// As [`forward`], with `grad_out` of the output's length.
pub fn grad_weight<T: Element>(x: &[T], grad_out: &[T], g: &Geometry) -> Vec<T> {
    assert_runs(
        g,
        ("input", x.len(), g.input_len()),
        ("output gradient", grad_out.len(), g.output_len()),
    );
    grad_weight_tiled(x, grad_out, g, Tile::for_geometry(g))
}

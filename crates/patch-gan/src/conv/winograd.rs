//! Winograd's minimal filtering F(2, 3) for stride-1 convolutions whose kernels are 3 or 1 taps
//! along each axis: the generators' 3x3x3 and the critics' 3x3 (a 1x3x3 here).
//!
//! Along an axis with 3 taps, two outputs `y = A^T [(G g) . (B^T d)]` come from a tile `d` of 4
//! inputs with 4 products instead of 6; an axis with 1 tap is left as it is. A 3D tile is the
//! product of its axes: 4x4x4 inputs give 2x2x2 outputs with 64 products per channel pair instead
//! of 216 (3.4x fewer), a 2D one 16 instead of 36 (2.25x). The products are, for each of the 64
//! (or 16) transformed positions, one matrix product `C_out x C_in` by `C_in x tiles`, which
//! `gemm` runs at full speed. All three passes of a convolution use it:
//!
//! - forward: input tiles transformed by `B^T`, weights by `G`, products by `A^T`;
//! - input gradient: the forward pass of the transposed convolution (kernel flipped, channels
//!   swapped, padding `k - 1 - p`), as in the im2col kernel;
//! - weight gradient: the adjoint of the forward pass in `g`, `dg = G^T [sum over tiles of
//!   (A dy) . (B^T d)]`: output-gradient tiles expanded by `A`, multiplied with the transformed
//!   input tiles (`C_out x tiles` by `tiles x C_in`, per position), and the sum mapped back by `G^T`.
//!
//! The transforms use the points 0, 1, -1 (entries 0, ±1, ±1/2), so F(2, 3) rounds about as well
//! as the direct sum (the tests hold it to the im2col kernel in f64 and f32). Work is split into
//! chunks of tiles of one batch item whose transformed inputs and products stay in the L2 cache.

use gemm::Parallelism;
use rayon::prelude::*;

use super::cpu::{Geometry, SharedMut};
use super::scratch::{at_least, Pooled};
use crate::element::Element;

/// Largest transformed tile: 4 x 4 x 4.
const MAX_TILE: usize = 64;

/// Elements of the transformed inputs plus products a chunk aims for (f32: 1 MiB, half of one
/// core's L2 cache here).
const CHUNK_TARGET_ELEMS: usize = 1 << 19;

/// Partial sums of the weight gradient, as in the im2col kernel: a fixed split of the chunks, so
/// the bits do not depend on thread scheduling.
const WEIGHT_GRAD_BLOCKS: usize = 8;

/// Whether the geometry has the shape F(2, 3) handles: stride 1, 3 taps along W and 1 or 3
/// along D and H, and padding at most `k - 1` (so the input gradient is a convolution too).
pub(crate) fn supports(g: &Geometry) -> bool {
    g.stride == 1
        && g.kernel[2] == 3
        && g.kernel.iter().all(|&k| k == 1 || k == 3)
        && (0..3).all(|a| g.padding[a] < g.kernel[a])
}

/// How one axis is tiled.
#[derive(Debug, Clone, Copy)]
struct Axis {
    /// Taps: 1 or 3.
    taps: usize,
    /// Outputs per tile: 1 or 2.
    outs: usize,
    /// Inputs per tile (`outs + taps - 1`): 1 or 4.
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
    /// Rows per chunk.
    chunk_rows: usize,
}

impl Plan {
    fn new(g: &Geometry) -> Self {
        let out = g.output();
        let axes = [0, 1, 2].map(|a| {
            let taps = g.kernel[a];
            let outs = if taps == 3 { 2 } else { 1 };
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
        let per_row = positions * (g.c_in + g.c_out) * axes[2].tiles;
        let rows = axes[0].tiles * axes[1].tiles;
        Self {
            axes,
            positions,
            rows,
            chunk_rows: (CHUNK_TARGET_ELEMS / per_row).clamp(1, rows),
        }
    }

    /// Tiles per chunk at most.
    fn chunk_tiles(&self) -> usize {
        self.chunk_rows * self.axes[2].tiles
    }

    /// Work items: `(batch item, first row, rows)`.
    fn chunks(&self, batch: usize) -> Vec<(usize, usize, usize)> {
        (0..batch)
            .flat_map(|n| {
                (0..self.rows)
                    .step_by(self.chunk_rows)
                    .map(move |r| (n, r, self.chunk_rows.min(self.rows - r)))
            })
            .collect()
    }

    /// The `(D, H)` tile indices of a row.
    fn row_tiles(&self, row: usize) -> (usize, usize) {
        (row / self.axes[1].tiles, row % self.axes[1].tiles)
    }

    /// Length of a row of input voxels covering a row of tiles (with the padding): `2 (tiles + 1)`,
    /// stored de-interleaved (even voxels, then odd ones) so that the W transform, whose tiles
    /// step by 2, reads every operand with unit stride and vectorises.
    fn input_width(&self) -> usize {
        2 * (self.axes[2].tiles + 1)
    }

    /// Length of a row of outputs of a row of tiles (the last tile may overhang the output):
    /// `2 tiles`, de-interleaved like the input rows.
    fn output_width(&self) -> usize {
        2 * self.axes[2].tiles
    }
}

/// Per-task buffers of rows of voxels, reused across chunks.
struct RowBuffers<T> {
    a: Vec<T>,
    b: Vec<T>,
}

impl<T: Element> RowBuffers<T> {
    /// Length of each of the two buffers for `plan`.
    fn len(plan: &Plan) -> usize {
        plan.positions.max(16) * plan.input_width().max(plan.output_width())
    }
}

/// Values a [`map_rows`] step handles at once: fixed-size blocks are what the compiler turns
/// into vector instructions (a plain loop over the rows kept a bounds check per element).
const LANES: usize = 8;

/// `dst` row `dst_rows[k]` (each `width` long) gets component `k` of `map` applied, element by
/// element, to the rows `src_rows` of `src`.
#[inline(always)]
fn map_rows<T: Element, const I: usize, const O: usize>(
    src: &[T],
    src_rows: [usize; I],
    dst: &mut [T],
    dst_rows: [usize; O],
    width: usize,
    map: impl Fn([T; I]) -> [T; O],
) {
    let ins = src_rows.map(|r| &src[r * width..][..width]);
    let mut start = 0;
    while start < width {
        let n = LANES.min(width - start);
        let mut block_in = [[T::ZERO; LANES]; I];
        let mut block_out = [[T::ZERO; LANES]; O];
        if n == LANES {
            for (block, row) in block_in.iter_mut().zip(&ins) {
                block.copy_from_slice(&row[start..start + LANES]);
            }
        } else {
            for (block, row) in block_in.iter_mut().zip(&ins) {
                block[..n].copy_from_slice(&row[start..start + n]);
            }
        }
        for lane in 0..LANES {
            let v = map(std::array::from_fn(|k| block_in[k][lane]));
            for k in 0..O {
                block_out[k][lane] = v[k];
            }
        }
        for (&row, block) in dst_rows.iter().zip(&block_out) {
            let at = row * width + start;
            if n == LANES {
                dst[at..at + LANES].copy_from_slice(block);
            } else {
                dst[at..at + n].copy_from_slice(&block[..n]);
            }
        }
        start += n;
    }
}

/// Applies a 4-to-4 / 4-to-2 / 2-to-4 map along the D axis (when it has 3 taps) and then the H
/// axis of a block of rows laid out `(d, h, row)`, from `src` (shape `dims`) into `dst`;
/// returns the new `(d, h)` shape and which buffer holds the result (`false`: `src`).
#[inline(always)]
fn map_d_then_h<T: Element, const I: usize, const O: usize>(
    bufs: &mut RowBuffers<T>,
    dims: (usize, usize),
    taps: (usize, usize),
    width: usize,
    map: impl Fn([T; I]) -> [T; O] + Copy,
) -> (usize, usize) {
    let (mut d, h) = dims;
    if taps.0 == 3 {
        for b in 0..h {
            map_rows(
                &bufs.a,
                std::array::from_fn(|k| k * h + b),
                &mut bufs.b,
                std::array::from_fn(|k| k * h + b),
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
                &bufs.a,
                std::array::from_fn(|k| a * h + k),
                &mut bufs.b,
                std::array::from_fn(|k| a * O + k),
                width,
                map,
            );
        }
        h2 = O;
        std::mem::swap(&mut bufs.a, &mut bufs.b);
    }
    (d, h2)
}

/// `B^T` along one axis of 4 inputs: `[d0 - d2, d1 + d2, d2 - d1, d1 - d3]`.
fn input_1d<T: Element>(d: [T; 4]) -> [T; 4] {
    [d[0] - d[2], d[1] + d[2], d[2] - d[1], d[1] - d[3]]
}

/// `A^T` along one axis: 4 products to 2 outputs, `[m0 + m1 + m2, m1 - m2 - m3]`.
fn output_1d<T: Element>(m: [T; 4]) -> [T; 2] {
    [m[0] + m[1] + m[2], m[1] - m[2] - m[3]]
}

/// `A` along one axis: 2 output gradients to 4, `[y0, y0 + y1, y0 - y1, -y1]`.
fn output_adjoint_1d<T: Element>(y: [T; 2]) -> [T; 4] {
    [y[0], y[0] + y[1], y[0] - y[1], T::ZERO - y[1]]
}

/// `G` along one axis: 3 taps to 4, `[g0, (g0 + g1 + g2) / 2, (g0 - g1 + g2) / 2, g2]`.
fn weight_1d(g: [f64; 3]) -> [f64; 4] {
    [
        g[0],
        (g[0] + g[1] + g[2]) / 2.0,
        (g[0] - g[1] + g[2]) / 2.0,
        g[2],
    ]
}

/// `G^T` along one axis: 4 transformed values back to 3 taps.
fn weight_adjoint_1d(u: [f64; 4]) -> [f64; 3] {
    [
        u[0] + (u[1] + u[2]) / 2.0,
        (u[1] - u[2]) / 2.0,
        (u[1] + u[2]) / 2.0 + u[3],
    ]
}

/// Applies a 1D map (`n_in` values to `n_out`) along `axis` of a row-major block of `shape`,
/// in place in `buf`; returns the new shape. Axes of length 1 that the map keeps are skipped.
fn along_axis<T: Copy, const I: usize, const O: usize>(
    buf: &mut [T; MAX_TILE],
    shape: [usize; 3],
    axis: usize,
    map: impl Fn([T; I]) -> [T; O],
) -> [usize; 3] {
    let mut out_shape = shape;
    out_shape[axis] = O;
    let src = *buf;
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
            let line: [T; I] = std::array::from_fn(|t| src[base + t * strides[axis]]);
            let mapped = map(line);
            let out_base = i * out_strides[a] + j * out_strides[b];
            for (t, v) in mapped.into_iter().enumerate() {
                buf[out_base + t * out_strides[axis]] = v;
            }
        }
    }
    out_shape
}

/// The transformed weights `U[position][c_out][c_in]` of `w` `(C_out, C_in, kd, kh, kw)`.
fn transform_weights<T: Element>(w: &[T], g: &Geometry, plan: &Plan) -> Vec<T> {
    let taps: usize = g.kernel.iter().product();
    let mut u = vec![T::ZERO; plan.positions * g.c_out * g.c_in];
    for pair in 0..g.c_out * g.c_in {
        let mut buf = [0f64; MAX_TILE];
        for (b, v) in buf.iter_mut().zip(&w[pair * taps..(pair + 1) * taps]) {
            *b = v.to_f64();
        }
        let mut shape = g.kernel;
        for axis in 0..3 {
            if g.kernel[axis] == 3 {
                shape = along_axis(&mut buf, shape, axis, weight_1d);
            }
        }
        for (pos, v) in buf[..plan.positions].iter().enumerate() {
            u[pos * g.c_out * g.c_in + pair] = T::from_f64(*v);
        }
    }
    u
}

/// Copies the input row `src` into `dst` (`input_width` long, de-interleaved: `dst[k]` is the
/// padded row's voxel `2k`, `dst[half + k]` voxel `2k + 1`), zeros in the padding.
#[inline(always)]
fn gather_input_row<T: Element>(dst: &mut [T], src: &[T], padding: usize) {
    dst.fill(T::ZERO);
    let half = dst.len() / 2;
    let (even, odd) = dst.split_at_mut(half);
    // Voxel i of `src` is voxel i + padding of the padded row.
    let (to_first, to_second) = if padding % 2 == 0 {
        (&mut even[padding / 2..], &mut odd[padding / 2..])
    } else {
        (&mut odd[padding / 2..], &mut even[padding / 2 + 1..])
    };
    for (d, v) in to_first.iter_mut().zip(src.iter().step_by(2)) {
        *d = *v;
    }
    for (d, v) in to_second.iter_mut().zip(src.iter().skip(1).step_by(2)) {
        *d = *v;
    }
}

/// Fills `v` (`positions x C_in x tiles` of the chunk, tiles in row order) with the chunk's
/// input tiles transformed by `B^T`: per channel and row of tiles, the rows of voxels under it
/// (zeros in the padding) are transformed along D and H as whole rows, then along W per tile.
#[inline(always)]
fn fill_transformed_inputs<T: Element>(
    v: &mut [T],
    bufs: &mut RowBuffers<T>,
    x_n: &[T],
    g: &Geometry,
    plan: &Plan,
    (row0, rows): (usize, usize),
) {
    let [ad, ah, aw] = plan.axes;
    let in_vox: usize = g.input.iter().product();
    let width = plan.input_width();
    let (tiles, half) = (rows * aw.tiles, aw.tiles + 1);
    for c in 0..g.c_in {
        let x_c = &x_n[c * in_vox..(c + 1) * in_vox];
        for r in 0..rows {
            let (td, th) = plan.row_tiles(row0 + r);
            for a in 0..ad.ins {
                let z = (td * ad.outs + a).wrapping_sub(ad.padding);
                for b in 0..ah.ins {
                    let y = (th * ah.outs + b).wrapping_sub(ah.padding);
                    let dst = &mut bufs.a[(a * ah.ins + b) * width..][..width];
                    // Wrapped (negative) indices are huge, so one comparison covers both sides.
                    if z < ad.input && y < ah.input {
                        let src = &x_c[(z * ah.input + y) * aw.input..][..aw.input];
                        gather_input_row(dst, src, aw.padding);
                    } else {
                        dst.fill(T::ZERO);
                    }
                }
            }
            let (nd, nh) =
                map_d_then_h(bufs, (ad.ins, ah.ins), (ad.taps, ah.taps), width, input_1d);
            let j0 = r * aw.tiles;
            for row in 0..nd * nh {
                let (even, odd) = bufs.a[row * width..(row + 1) * width].split_at(half);
                let (e0, e1, o0, o1) = (&even[..half - 1], &even[1..], &odd[..half - 1], &odd[1..]);
                let at = |xi: usize| ((row * 4 + xi) * g.c_in + c) * tiles + j0;
                // B^T on (x[2t], x[2t+1], x[2t+2], x[2t+3]) = (e0, o0, e1, o1).
                let dst = &mut v[at(0)..][..aw.tiles];
                dst.iter_mut()
                    .zip(e0.iter().zip(e1))
                    .for_each(|(d, (a, b))| *d = *a - *b);
                let dst = &mut v[at(1)..][..aw.tiles];
                dst.iter_mut()
                    .zip(o0.iter().zip(e1))
                    .for_each(|(d, (a, b))| *d = *a + *b);
                let dst = &mut v[at(2)..][..aw.tiles];
                dst.iter_mut()
                    .zip(e1.iter().zip(o0))
                    .for_each(|(d, (a, b))| *d = *a - *b);
                let dst = &mut v[at(3)..][..aw.tiles];
                dst.iter_mut()
                    .zip(o0.iter().zip(o1))
                    .for_each(|(d, (a, b))| *d = *a - *b);
            }
        }
    }
}

/// The outputs of one row of tiles of channel `c`: `A^T` along W per tile from the products
/// `m` (`positions x C_out x tiles`), then along H and D over whole rows. The result, in
/// `bufs.a`, is `outs_d x outs_h` rows of `output_width` values, de-interleaved.
#[inline(always)]
fn transform_output_row<T: Element>(
    bufs: &mut RowBuffers<T>,
    m: &[T],
    (c, c_out): (usize, usize),
    plan: &Plan,
    (j0, tiles): (usize, usize),
) {
    let [ad, ah, aw] = plan.axes;
    let width = plan.output_width();
    for row in 0..ad.ins * ah.ins {
        let (even, odd) = bufs.a[row * width..(row + 1) * width].split_at_mut(aw.tiles);
        let at = |xi: usize| &m[((row * 4 + xi) * c_out + c) * tiles + j0..][..aw.tiles];
        let (m0, m1, m2, m3) = (at(0), at(1), at(2), at(3));
        for (t, (e, o)) in even.iter_mut().zip(odd.iter_mut()).enumerate() {
            [*e, *o] = output_1d([m0[t], m1[t], m2[t], m3[t]]);
        }
    }
    map_d_then_h(bufs, (ad.ins, ah.ins), (ad.taps, ah.taps), width, output_1d);
}

/// The output gradient of one row of tiles of channel `c` expanded by `A` into `z`
/// (`positions x C_out x tiles`): rows of `grad_out` (zeros past the output, de-interleaved)
/// expanded along D and H, then along W per tile.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn expand_output_grad_row<T: Element>(
    z: &mut [T],
    bufs: &mut RowBuffers<T>,
    go_c: &[T],
    (c, c_out): (usize, usize),
    g: &Geometry,
    plan: &Plan,
    (row, j0, tiles): (usize, usize, usize),
) {
    let [ad, ah, aw] = plan.axes;
    let out = g.output();
    let width = plan.output_width();
    let (td, th) = plan.row_tiles(row);
    for a in 0..ad.outs {
        for b in 0..ah.outs {
            let (zz, yy) = (td * ad.outs + a, th * ah.outs + b);
            let (even, odd) = bufs.a[(a * ah.outs + b) * width..][..width].split_at_mut(aw.tiles);
            if zz < out[0] && yy < out[1] {
                let src = &go_c[(zz * out[1] + yy) * out[2]..][..out[2]];
                let at = |i: usize| src.get(i).copied().unwrap_or(T::ZERO);
                for (t, (e, o)) in even.iter_mut().zip(odd.iter_mut()).enumerate() {
                    *e = at(2 * t);
                    *o = at(2 * t + 1);
                }
            } else {
                even.fill(T::ZERO);
                odd.fill(T::ZERO);
            }
        }
    }
    let (nd, nh) = map_d_then_h(
        bufs,
        (ad.outs, ah.outs),
        (ad.taps, ah.taps),
        width,
        output_adjoint_1d,
    );
    for r in 0..nd * nh {
        let (even, odd) = bufs.a[r * width..(r + 1) * width].split_at(aw.tiles);
        let at = |xi: usize| ((r * 4 + xi) * c_out + c) * tiles + j0;
        // A on (y[2t], y[2t+1]) = (even, odd): (y0, y0 + y1, y0 - y1, -y1).
        z[at(0)..][..aw.tiles].copy_from_slice(even);
        let dst = &mut z[at(1)..][..aw.tiles];
        dst.iter_mut()
            .zip(even.iter().zip(odd))
            .for_each(|(d, (a, b))| *d = *a + *b);
        let dst = &mut z[at(2)..][..aw.tiles];
        dst.iter_mut()
            .zip(even.iter().zip(odd))
            .for_each(|(d, (a, b))| *d = *a - *b);
        let dst = &mut z[at(3)..][..aw.tiles];
        dst.iter_mut().zip(odd).for_each(|(d, b)| *d = T::ZERO - *b);
    }
}

/// `dst (m x n) = lhs (m x k) * rhs (k x n)` (or `+=` with `accumulate`), with the row and
/// column strides given as `(row, col)`.
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
/// gradients), rows. Every chunk writes each value it reads first, so a scratch is reused from
/// the thread's pool as it is ([`scratch_for`]).
struct ForwardScratch<T> {
    v: Vec<T>,
    m: Vec<T>,
    bufs: RowBuffers<T>,
}

// By hand: a derive would ask `T: Default`.
impl<T> Default for ForwardScratch<T> {
    fn default() -> Self {
        Self {
            v: Vec::new(),
            m: Vec::new(),
            bufs: RowBuffers {
                a: Vec::new(),
                b: Vec::new(),
            },
        }
    }
}

/// A pooled [`ForwardScratch`] large enough for a pass of `plan`.
fn scratch_for<T: Element>(plan: &Plan, c_in: usize, c_out: usize) -> Pooled<ForwardScratch<T>> {
    let (p, most) = (plan.positions, plan.chunk_tiles());
    let mut scratch = Pooled::<ForwardScratch<T>>::take();
    let rows = RowBuffers::<T>::len(plan);
    let ForwardScratch { v, m, bufs } = &mut *scratch;
    at_least(v, p * c_in * most);
    at_least(m, p * c_out * most);
    at_least(&mut bufs.a, rows);
    at_least(&mut bufs.b, rows);
    scratch
}

/// One chunk of a forward pass: transform its input tiles, multiply per position, transform
/// the products back and write the outputs.
#[inline(always)]
fn forward_chunk<T: Element>(
    pass: &ForwardPass<'_, T>,
    scratch: &mut ForwardScratch<T>,
    (n, row0, rows): (usize, usize, usize),
) {
    let (g, plan) = (pass.g, pass.plan);
    let (p, ci, co) = (plan.positions, g.c_in, g.c_out);
    let [ad, ah, aw] = plan.axes;
    let in_vox: usize = g.input.iter().product();
    let out = g.output();
    let out_vox: usize = out.iter().product();
    let ForwardScratch { v, m, bufs } = scratch;
    let tiles = rows * aw.tiles;
    fill_transformed_inputs(v, bufs, &pass.x[n * ci * in_vox..], g, plan, (row0, rows));
    for pos in 0..p {
        // SAFETY: U[pos] is co x ci, V[pos] ci x tiles, M[pos] co x tiles, all in bounds.
        unsafe {
            matmul(
                (co, tiles, ci),
                (m[pos * co * tiles..].as_mut_ptr(), tiles as isize, 1),
                (pass.u[pos * co * ci..].as_ptr(), ci as isize, 1),
                (v[pos * ci * tiles..].as_ptr(), tiles as isize, 1),
                false,
            )
        };
    }
    let width = plan.output_width();
    for r in 0..rows {
        let (td, th) = plan.row_tiles(row0 + r);
        for c in 0..co {
            transform_output_row(bufs, m, (c, co), plan, (r * aw.tiles, tiles));
            for a in 0..ad.outs {
                for b in 0..ah.outs {
                    let (z, yy) = (td * ad.outs + a, th * ah.outs + b);
                    if z >= ad.output || yy >= ah.output {
                        continue;
                    }
                    let (even, odd) =
                        bufs.a[(a * ah.outs + b) * width..][..width].split_at(aw.tiles);
                    let at = (n * co + c) * out_vox + (z * out[1] + yy) * out[2];
                    // SAFETY: in bounds of `y`; this output row belongs to this chunk's tiles
                    // only, and no other reference to it exists.
                    let row =
                        unsafe { std::slice::from_raw_parts_mut(pass.y.ptr().add(at), out[2]) };
                    let mut pairs = row.chunks_exact_mut(2);
                    for (pair, (e, o)) in (&mut pairs).zip(even.iter().zip(odd)) {
                        pair[0] = *e;
                        pair[1] = *o;
                    }
                    if let [last] = pairs.into_remainder() {
                        *last = even[out[2] / 2];
                    }
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
unsafe fn forward_chunk_avx2<T: Element>(
    pass: &ForwardPass<'_, T>,
    scratch: &mut ForwardScratch<T>,
    chunk: (usize, usize, usize),
) {
    forward_chunk(pass, scratch, chunk)
}

/// Whether this CPU runs the AVX2 builds of the chunk functions (the results are the same bits:
/// Rust does not fuse multiplies and adds, and the vectorised loops do not reorder sums).
fn has_avx2() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::is_x86_feature_detected!("avx2")
    }
    #[cfg(not(target_arch = "x86_64"))]
    false
}

/// `y = conv3d(x, w)` without bias, as [`super::cpu::forward`], for a geometry [`supports`] accepts.
pub(crate) fn forward<T: Element>(x: &[T], w: &[T], g: &Geometry) -> Vec<T> {
    let plan = Plan::new(g);
    let u = transform_weights(w, g, &plan);
    let out_vox: usize = g.output().iter().product();
    let mut y = vec![T::ZERO; g.batch * g.c_out * out_vox];
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
                return unsafe { forward_chunk_avx2(&pass, scratch, chunk) };
            }
            forward_chunk(&pass, scratch, chunk)
        },
    );
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
/// output-gradient tiles (into `scratch.m`), and add their products per position to `du`.
#[inline(always)]
fn weight_grad_chunk<T: Element>(
    pass: &WeightGradPass<'_, T>,
    scratch: &mut ForwardScratch<T>,
    du: &mut [T],
    (n, row0, rows): (usize, usize, usize),
) {
    let (g, plan) = (pass.g, pass.plan);
    let (p, ci, co) = (plan.positions, g.c_in, g.c_out);
    let in_vox: usize = g.input.iter().product();
    let out_vox: usize = g.output().iter().product();
    let aw = plan.axes[2];
    let ForwardScratch { v, m: z, bufs } = scratch;
    let tiles = rows * aw.tiles;
    fill_transformed_inputs(v, bufs, &pass.x[n * ci * in_vox..], g, plan, (row0, rows));
    for c in 0..co {
        let go_c = &pass.grad_out[(n * co + c) * out_vox..][..out_vox];
        for r in 0..rows {
            let at = (row0 + r, r * aw.tiles, tiles);
            expand_output_grad_row(z, bufs, go_c, (c, co), g, plan, at);
        }
    }
    for pos in 0..p {
        // SAFETY: dU[pos] is co x ci, Z[pos] co x tiles, V[pos]^T tiles x ci.
        unsafe {
            matmul(
                (co, ci, tiles),
                (du[pos * co * ci..].as_mut_ptr(), ci as isize, 1),
                (z[pos * co * tiles..].as_ptr(), tiles as isize, 1),
                (v[pos * ci * tiles..].as_ptr(), 1, tiles as isize),
                true,
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
unsafe fn weight_grad_chunk_avx2<T: Element>(
    pass: &WeightGradPass<'_, T>,
    scratch: &mut ForwardScratch<T>,
    du: &mut [T],
    chunk: (usize, usize, usize),
) {
    weight_grad_chunk(pass, scratch, du, chunk)
}

/// Gradient of `sum(grad_out * conv3d(x, w))` with respect to `w`, as
/// [`super::cpu::grad_weight`].
pub(crate) fn grad_weight<T: Element>(x: &[T], grad_out: &[T], g: &Geometry) -> Vec<T> {
    let plan = Plan::new(g);
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
            let mut du = vec![T::ZERO; p * co * ci];
            let mut scratch = scratch_for(&plan, ci, co);
            for &chunk in block {
                #[cfg(target_arch = "x86_64")]
                if avx2 {
                    // SAFETY: the CPU has AVX2 (checked above).
                    unsafe { weight_grad_chunk_avx2(&pass, &mut scratch, &mut du, chunk) };
                    continue;
                }
                weight_grad_chunk(&pass, &mut scratch, &mut du, chunk);
            }
            du
        })
        .collect();
    let mut du = vec![0f64; p * co * ci];
    for partial in partials {
        du.iter_mut()
            .zip(partial)
            .for_each(|(a, b)| *a += b.to_f64());
    }
    let taps: usize = g.kernel.iter().product();
    let mut dw = vec![T::ZERO; co * ci * taps];
    for pair in 0..co * ci {
        let mut buf = [0f64; MAX_TILE];
        for (pos, b) in buf[..p].iter_mut().enumerate() {
            *b = du[pos * co * ci + pair];
        }
        let mut shape = plan.axes.map(|a| a.ins);
        for axis in 0..3 {
            if g.kernel[axis] == 3 {
                shape = along_axis(&mut buf, shape, axis, weight_adjoint_1d);
            }
        }
        for (t, v) in buf[..taps].iter().enumerate() {
            dw[pair * taps + t] = T::from_f64(*v);
        }
    }
    dw
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::conv::cpu;

    /// Deterministic values in [-1, 1).
    fn values(n: usize, seed: u64) -> Vec<f64> {
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
            for input in [[5, 6, 7], [4, 4, 4], [3, 8, 5]] {
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

    #[test]
    fn all_three_passes_match_the_im2col_kernel_in_f64() {
        for (i, g) in geometries().into_iter().enumerate() {
            assert!(supports(&g), "{g:?}");
            let in_len = g.batch * g.c_in * g.input.iter().product::<usize>();
            let out_len = g.batch * g.c_out * g.output().iter().product::<usize>();
            let w_len = g.c_out * g.c_in * g.kernel.iter().product::<usize>();
            let x = values(in_len, 3 * i as u64);
            let w = values(w_len, 3 * i as u64 + 1);
            let go = values(out_len, 3 * i as u64 + 2);
            let pairs = [
                (forward(&x, &w, &g), cpu::forward(&x, &w, &g)),
                (grad_input(&go, &w, &g), cpu::grad_input(&go, &w, &g)),
                (grad_weight(&x, &go, &g), cpu::grad_weight(&x, &go, &g)),
            ];
            for (pass, (ours, reference)) in pairs.iter().enumerate() {
                let err = max_rel_diff(ours, reference);
                assert!(err < 1e-13, "{g:?} pass {pass}: relative error {err}");
            }
        }
    }

    #[test]
    fn f32_rounding_stays_at_the_direct_sums_level() {
        let g = Geometry {
            batch: 1,
            c_in: 32,
            c_out: 32,
            input: [9, 10, 11],
            kernel: [3, 3, 3],
            padding: [1, 1, 1],
            stride: 1,
        };
        let x = values(32 * 990, 7);
        let w: Vec<f64> = values(32 * 32 * 27, 8).iter().map(|v| v * 0.05).collect();
        let exact = cpu::forward(&x, &w, &g);
        let as_f32 = |v: &[f64]| v.iter().map(|&x| x as f32).collect::<Vec<f32>>();
        let widen = |v: Vec<f32>| v.into_iter().map(f64::from).collect::<Vec<f64>>();
        let ours = widen(forward(&as_f32(&x), &as_f32(&w), &g));
        let direct = widen(cpu::forward(&as_f32(&x), &as_f32(&w), &g));
        let (ours_err, direct_err) = (max_rel_diff(&ours, &exact), max_rel_diff(&direct, &exact));
        assert!(
            ours_err < 4.0 * direct_err.max(1e-7),
            "{ours_err} vs im2col {direct_err}"
        );
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

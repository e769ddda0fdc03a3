//! CPU kernels of the convolution: forward, input gradient and weight gradient.
//!
//! Every convolution here is 3D with a per-axis kernel and padding; a 2D one is a 3D one with
//! depth 1 and a kernel one tap deep. All three kernels work on chunks of output rows (an output
//! row is the `W_out` voxels of one `(n, d, h)`). For each chunk a small im2col matrix `cols` of
//! shape `(C_in kd kh kw, rows * W_out)` is filled from the
//! input (zeros where the kernel overhangs the padding) and handed to `gemm`. The chunk is sized so
//! that `cols` stays in the L2 cache, which is what makes this faster than a whole-volume im2col
//! (27x the input, far beyond any cache) followed by one large matrix product.
//!
//! [`forward`] and [`grad_weight`] only ask a geometry for its chunks and how to fill their
//! columns ([`Columns`]), so the convolution on active sites (`super::active`) runs them too.

use gemm::Parallelism;
use rayon::prelude::*;

use super::scratch::pooled_vec;
use crate::element::Element;

/// Shape of one batched 3D convolution.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Geometry {
    pub batch: usize,
    pub c_in: usize,
    pub c_out: usize,
    /// Input `[D, H, W]`.
    pub input: [usize; 3],
    /// Kernel taps `[kd, kh, kw]`.
    pub kernel: [usize; 3],
    /// Zeros before and after each of `[D, H, W]`.
    pub padding: [usize; 3],
    pub stride: usize,
}

/// Elements of `cols` a chunk aims for: 2^18 f32 values = 1 MiB, half of one core's L2 here.
const COLS_TARGET_ELEMS: usize = 1 << 18;

impl Geometry {
    /// Output `[D, H, W]`; callers have checked `n + 2 padding >= kernel` on every axis.
    pub fn output(&self) -> [usize; 3] {
        [0, 1, 2].map(|a| (self.input[a] + 2 * self.padding[a] - self.kernel[a]) / self.stride + 1)
    }

    /// The transposed convolution as a forward one, whose output is this one's input: channels
    /// swapped, padding `k - 1 - p`. Exists for stride 1 and padding below the kernel on every
    /// axis (a larger padding or a stride has no such padding).
    pub fn transposed(&self) -> Option<Geometry> {
        (self.stride == 1 && (0..3).all(|a| self.padding[a] < self.kernel[a])).then(|| Geometry {
            batch: self.batch,
            c_in: self.c_out,
            c_out: self.c_in,
            input: self.output(),
            kernel: self.kernel,
            padding: [0, 1, 2].map(|a| self.kernel[a] - 1 - self.padding[a]),
            stride: 1,
        })
    }
}

/// A work item of [`forward`] and [`grad_weight`]: `(batch item, first output column, columns)`.
pub(crate) type Chunk = (usize, usize, usize);

/// What the im2col kernels need to know of a convolution: its channels, the length of one
/// im2col column (`C_in` times the kernel's taps), how its output columns split into
/// cache-sized chunks, and how to fill a chunk's columns from the input. Implemented by the
/// dense [`Geometry`] (output columns are voxels, a chunk is whole output rows) and by the
/// active-set convolution (columns are active sites, see `super::active`).
pub(crate) trait Columns: Sync {
    fn batch(&self) -> usize;
    fn c_in(&self) -> usize;
    fn c_out(&self) -> usize;
    /// Kernel taps per input channel.
    fn taps(&self) -> usize;
    /// Values per channel of one batch item of the input.
    fn in_len(&self) -> usize;
    /// Output columns (values per channel) of one batch item.
    fn out_len(&self) -> usize;
    /// The work items, columns of one batch item each.
    fn chunks(&self) -> Vec<Chunk>;
    /// Fills `cols` (`patch_len` rows of `chunk.2` values) from `x_n`, the chunk's batch item
    /// (`C_in x in_len`). Row `r = c taps + tap` matches the weight layout `(C_out, C_in, taps)`.
    fn fill<T: Element>(&self, cols: &mut [T], x_n: &[T], chunk: Chunk);

    /// Length of one im2col column: every input channel times every kernel tap.
    fn patch_len(&self) -> usize {
        self.c_in() * self.taps()
    }

    fn max_chunk_cols(&self) -> usize {
        self.chunks()
            .iter()
            .map(|&(_, _, cols)| cols)
            .max()
            .unwrap_or(0)
    }
}

/// Columns per chunk for im2col columns of `patch_len` values: `cols` stays near
/// [`COLS_TARGET_ELEMS`], rounded down to whole multiples of `unit` (at least one unit).
pub(crate) fn chunk_columns(patch_len: usize, unit: usize) -> usize {
    (COLS_TARGET_ELEMS / (patch_len * unit)).max(1) * unit
}

impl Columns for Geometry {
    fn batch(&self) -> usize {
        self.batch
    }

    fn c_in(&self) -> usize {
        self.c_in
    }

    fn c_out(&self) -> usize {
        self.c_out
    }

    fn taps(&self) -> usize {
        self.kernel.iter().product()
    }

    fn in_len(&self) -> usize {
        self.input.iter().product()
    }

    fn out_len(&self) -> usize {
        self.output().iter().product()
    }

    /// Whole output rows (the `W_out` voxels of one `(n, d, h)`) per chunk.
    fn chunks(&self) -> Vec<Chunk> {
        let [d_out, h_out, w_out] = self.output();
        let rows = d_out * h_out;
        let per_chunk = (chunk_columns(self.patch_len(), w_out) / w_out).min(rows);
        (0..self.batch)
            .flat_map(|n| {
                (0..rows)
                    .step_by(per_chunk)
                    .map(move |r| (n, r * w_out, per_chunk.min(rows - r) * w_out))
            })
            .collect()
    }

    fn fill<T: Element>(&self, cols: &mut [T], x_n: &[T], (_, first, len): Chunk) {
        let w_out = self.output()[2];
        fill_cols(cols, x_n, self, first / w_out, len / w_out);
    }
}

/// A pointer the forward passes share between rayon tasks that write disjoint outputs.
#[derive(Clone, Copy)]
pub(crate) struct SharedMut<T>(pub(crate) *mut T);
// SAFETY: every task writes a disjoint set of elements (its own output rows or tiles), see
// `forward` here and in `winograd`.
unsafe impl<T: Send> Send for SharedMut<T> {}
unsafe impl<T: Send> Sync for SharedMut<T> {}

impl<T> SharedMut<T> {
    /// A method, not a field access, so closures capture the whole (Sync) wrapper.
    pub(crate) fn ptr(self) -> *mut T {
        self.0
    }
}

/// Copies one input row into one output row of `cols`: `seg[w] = src[stride w + tap - padding]`,
/// zero where that index falls into the padding.
fn copy_row<T: Element>(seg: &mut [T], src: &[T], tap: usize, padding: usize, stride: usize) {
    let len = seg.len();
    // First w with stride*w + tap >= padding, and first w with stride*w + tap - padding >= src.len().
    let lo = padding.saturating_sub(tap).div_ceil(stride).min(len);
    let hi = (src.len() + padding)
        .saturating_sub(tap)
        .div_ceil(stride)
        .clamp(lo, len);
    seg[..lo].fill(T::ZERO);
    seg[hi..].fill(T::ZERO);
    if stride == 1 {
        let start = lo + tap - padding;
        seg[lo..hi].copy_from_slice(&src[start..start + hi - lo]);
    } else {
        for (w, v) in seg[lo..hi].iter_mut().enumerate() {
            *v = src[stride * (lo + w) + tap - padding];
        }
    }
}

/// Fills `cols` (`patch_len` rows of `rows * W_out` values) for output rows `row0..row0 + rows` of
/// the batch item `x_n` (`C_in x D x H x W`). Row `r = ((c kd + td) kh + th) kw + tw` of `cols`
/// matches the weight layout `(C_out, C_in, kd, kh, kw)`.
fn fill_cols<T: Element>(cols: &mut [T], x_n: &[T], g: &Geometry, row0: usize, rows: usize) {
    let [d_in, h_in, w_in] = g.input;
    let (taps, in_vox) = (g.taps(), g.in_len());
    let [_, h_out, w_out] = g.output();
    let ([_, kh, kw], [pd, ph, pw], s) = (g.kernel, g.padding, g.stride);
    let nc = rows * w_out;
    for (r, dst) in cols.chunks_exact_mut(nc).enumerate() {
        let tap = r % taps;
        let (td, th, tw) = (tap / (kh * kw), (tap / kw) % kh, tap % kw);
        let x_c = &x_n[(r / taps) * in_vox..];
        for (t, seg) in dst.chunks_exact_mut(w_out).enumerate() {
            let (od, oh) = ((row0 + t) / h_out, (row0 + t) % h_out);
            let (id, ih) = (
                (s * od + td).wrapping_sub(pd),
                (s * oh + th).wrapping_sub(ph),
            );
            // Wrapped (negative) indices are huge, so one comparison covers both sides.
            if id >= d_in || ih >= h_in {
                seg.fill(T::ZERO);
            } else {
                let start = (id * h_in + ih) * w_in;
                copy_row(seg, &x_c[start..start + w_in], tw, pw, s);
            }
        }
    }
}

/// `y = conv(x, w)` without bias: `x` is `(N, C_in, in_len)`, `w` is `(C_out, C_in, taps)`, the
/// result `(N, C_out, out_len)`, all contiguous (for a [`Geometry`]: `(N, C_in, D, H, W)` to
/// `(N, C_out, D_out, H_out, W_out)`).
pub(crate) fn forward<T: Element>(x: &[T], w: &[T], g: &impl Columns) -> Vec<T> {
    let (in_len, out_len, patch) = (g.in_len(), g.out_len(), g.patch_len());
    let (c_in, c_out) = (g.c_in(), g.c_out());
    let mut out = vec![T::ZERO; g.batch() * c_out * out_len];
    let dst = SharedMut(out.as_mut_ptr());
    let max_cols = g.max_chunk_cols();
    g.chunks().into_par_iter().for_each_init(
        || pooled_vec::<T>(patch * max_cols),
        |cols, chunk| {
            let (n, first, nc) = chunk;
            let cols = &mut cols[..patch * nc];
            g.fill(cols, &x[n * c_in * in_len..], chunk);
            // SAFETY: `out` outlives the parallel loop; this task writes only columns
            // `first .. first + nc` of the `C_out` rows of item `n` (row stride `out_len`), which
            // no other chunk covers; `w` and `cols` are read-only with the strides given.
            unsafe {
                let dst = dst.ptr().add(n * c_out * out_len + first);
                gemm::gemm(
                    c_out,
                    nc,
                    patch,
                    dst,
                    1,
                    out_len as isize,
                    false,
                    w.as_ptr(),
                    1,
                    patch as isize,
                    cols.as_ptr(),
                    1,
                    nc as isize,
                    T::ZERO,
                    T::ONE,
                    false,
                    false,
                    false,
                    Parallelism::None,
                );
            }
        },
    );
    out
}

/// Partial sums of the weight gradient: the chunks are split into this many runs of
/// consecutive chunks, each summed in order into its own buffer, and the buffers are added in
/// order. The split depends only on the chunk count, so the gradient's bits do not depend on
/// thread scheduling (a rayon `fold`/`reduce` splits where work stealing happens to, and made
/// training differ from run to run in the last bits).
const WEIGHT_GRAD_BLOCKS: usize = 8;

/// Gradient of `sum(grad_out * conv(x, w))` with respect to `w`: shape `(C_out, C_in, taps)`.
pub(crate) fn grad_weight<T: Element>(x: &[T], grad_out: &[T], g: &impl Columns) -> Vec<T> {
    let (in_len, out_len, patch) = (g.in_len(), g.out_len(), g.patch_len());
    let (c_in, c_out) = (g.c_in(), g.c_out());
    let size = c_out * patch;
    let max_cols = g.max_chunk_cols();
    let chunks = g.chunks();
    let per_block = chunks.len().div_ceil(WEIGHT_GRAD_BLOCKS).max(1);
    let partials: Vec<Vec<T>> = chunks
        .par_chunks(per_block)
        .map(|block| {
            let mut acc = vec![T::ZERO; size];
            let mut cols = pooled_vec::<T>(patch * max_cols);
            for &chunk in block {
                let (n, first, nc) = chunk;
                let chunk_cols = &mut cols[..patch * nc];
                g.fill(chunk_cols, &x[n * c_in * in_len..], chunk);
                let go = &grad_out[n * c_out * out_len + first..];
                // acc (C_out x patch) += grad chunk (C_out x nc) * cols^T (nc x patch).
                // SAFETY: all pointers cover the ranges implied by the dimensions and strides.
                unsafe {
                    gemm::gemm(
                        c_out,
                        patch,
                        nc,
                        acc.as_mut_ptr(),
                        1,
                        patch as isize,
                        true,
                        go.as_ptr(),
                        1,
                        out_len as isize,
                        chunk_cols.as_ptr(),
                        nc as isize,
                        1,
                        T::ONE,
                        T::ONE,
                        false,
                        false,
                        false,
                        Parallelism::None,
                    );
                }
            }
            acc
        })
        .collect();
    let mut total = vec![T::ZERO; size];
    for partial in partials {
        total.iter_mut().zip(partial).for_each(|(a, b)| *a = *a + b);
    }
    total
}

/// The kernel of the transposed convolution: `w` `(C_out, C_in, kd, kh, kw)` flipped on its
/// three spatial axes (the taps reversed), with its two channel axes swapped.
pub(crate) fn flipped_transposed<T: Element>(w: &[T], g: &impl Columns) -> Vec<T> {
    let (taps, c_in, c_out) = (g.taps(), g.c_in(), g.c_out());
    let mut flipped = vec![T::ZERO; w.len()];
    for o in 0..c_out {
        for c in 0..c_in {
            for t in 0..taps {
                flipped[(c * c_out + o) * taps + t] = w[(o * c_in + c) * taps + taps - 1 - t];
            }
        }
    }
    flipped
}

/// Gradient of `sum(grad_out * conv3d(x, w))` with respect to `x`: shape `(N, C_in, D, H, W)`.
///
/// This is a transposed convolution, computed as a forward one with the kernel flipped on all
/// three axes and its two channel axes swapped. With stride 1 and padding below the kernel it is
/// [`Geometry::transposed`]'s convolution of the output gradient as it is; otherwise the output
/// gradient is first scattered into a zero grid of size `input + k - 1` per axis (entry `o` lands
/// at `stride o + k - 1 - padding`, which also undoes the stride) and convolved without padding.
pub(crate) fn grad_input<T: Element>(grad_out: &[T], w: &[T], g: &Geometry) -> Vec<T> {
    let (k, s) = (g.kernel, g.stride);
    if let Some(transposed) = g.transposed() {
        // Nothing to undo: the zeros the scatter would put around the output gradient are the
        // forward kernel's own padding, which it never stores.
        return forward(grad_out, &flipped_transposed(w, g), &transposed);
    }
    let out = g.output();
    let grid = [0, 1, 2].map(|a| g.input[a] + k[a] - 1);
    let grid_vox: usize = grid.iter().product();
    let out_vox = g.out_len();
    let shift = [0, 1, 2].map(|a| (k[a] - 1) as isize - g.padding[a] as isize);
    let mut scattered = vec![T::ZERO; g.batch * g.c_out * grid_vox];
    scattered
        .par_chunks_mut(grid_vox)
        .zip(grad_out.par_chunks(out_vox))
        .for_each(|(dst, src)| {
            for (i, &v) in src.iter().enumerate() {
                let o = [i / (out[1] * out[2]), (i / out[2]) % out[1], i % out[2]];
                let pos = [0, 1, 2].map(|a| (s * o[a]) as isize + shift[a]);
                // With padding > k - 1 an output can see padding only; its gradient reaches no input.
                if pos
                    .iter()
                    .zip(grid)
                    .all(|(&p, n)| (0..n as isize).contains(&p))
                {
                    let [pd, ph, pw] = pos.map(|p| p as usize);
                    dst[(pd * grid[1] + ph) * grid[2] + pw] = v;
                }
            }
        });
    let flipped = flipped_transposed(w, g);
    let transposed = Geometry {
        batch: g.batch,
        c_in: g.c_out,
        c_out: g.c_in,
        input: grid,
        kernel: k,
        padding: [0; 3],
        stride: 1,
    };
    forward(&scattered, &flipped, &transposed)
}

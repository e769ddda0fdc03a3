//! The im2col + `gemm` kernels of the convolution: forward, input gradient and weight gradient,
//! for any kernel size, padding and stride.
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
//! columns ([`Columns`]), so other geometries (patch-gan's convolution on active sites) run them
//! too.

use gemm::Parallelism;
use rayon::prelude::*;

use crate::element::Element;
use crate::geometry::{assert_valid, Geometry};
use crate::output::SharedMut;
use crate::scratch::pooled_vec;

/// Elements of `cols` a chunk aims for: 2^18 f32 values = 1 MiB, half of one core's L2 here.
const COLS_TARGET_ELEMS: usize = 1 << 18;

/// A work item of [`forward`] and [`grad_weight`]: `(batch item, first output column, columns)`.
pub type Chunk = (usize, usize, usize);

/// What the im2col kernels need to know of a convolution: its channels, the length of one
/// im2col column (`C_in` times the kernel's taps), how its output columns split into
/// cache-sized chunks, and how to fill a chunk's columns from the input. Implemented by the
/// dense [`Geometry`] (output columns are voxels, a chunk is whole output rows) and by
/// patch-gan's convolution on active sites (columns are active sites).
///
/// The kernels read each size once per call and check the slices and chunks against them
/// (panicking on a mismatch), so an implementation that gets them wrong gives wrong values or
/// a panic, never undefined behaviour.
pub trait Columns: Sync {
    /// Batch items.
    fn batch(&self) -> usize;
    /// Input channels.
    fn c_in(&self) -> usize;
    /// Output channels.
    fn c_out(&self) -> usize;
    /// Kernel taps per input channel.
    fn taps(&self) -> usize;
    /// Values per channel of one batch item of the input.
    fn in_len(&self) -> usize;
    /// Output columns (values per channel) of one batch item.
    fn out_len(&self) -> usize;
    /// The work items, columns of one batch item each: every chunk inside the batch and the
    /// output columns, no two overlapping.
    fn chunks(&self) -> Vec<Chunk>;
    /// Fills `cols` (`patch_len` rows of `chunk.2` values) from `x_n`, the chunk's batch item
    /// (`C_in x in_len`). Row `r = c taps + tap` matches the weight layout `(C_out, C_in, taps)`.
    fn fill<T: Element>(&self, cols: &mut [T], x_n: &[T], chunk: Chunk);

    /// Length of one im2col column: every input channel times every kernel tap.
    fn patch_len(&self) -> usize {
        self.c_in() * self.taps()
    }
}

/// `xs`' product, or a panic naming `what` if it overflows.
#[track_caller]
fn product(what: &str, xs: &[usize]) -> usize {
    xs.iter()
        .try_fold(1usize, |acc, &x| acc.checked_mul(x))
        .unwrap_or_else(|| panic!("conv-kernels: the {what} {xs:?} overflow"))
}

/// The sizes of a [`Columns`], read once: what the kernels' pointer arithmetic runs on.
struct Sizes {
    batch: usize,
    c_in: usize,
    c_out: usize,
    in_len: usize,
    out_len: usize,
    /// `c_in taps`.
    patch: usize,
}

impl Sizes {
    #[track_caller]
    fn of(g: &impl Columns) -> Self {
        let (c_in, taps) = (g.c_in(), g.taps());
        Self {
            batch: g.batch(),
            c_in,
            c_out: g.c_out(),
            in_len: g.in_len(),
            out_len: g.out_len(),
            patch: product("im2col column sizes", &[c_in, taps]),
        }
    }

    /// Panics unless `len`, the length of the slice `what`, is `dims`' product.
    #[track_caller]
    fn check(&self, what: &str, len: usize, dims: &[usize]) {
        let expected = product(what, dims);
        assert_eq!(
            len, expected,
            "conv-kernels: {what} of {len} values, expected {dims:?}"
        );
    }

    /// `g`'s chunks, after checking that each lies inside the batch and the output columns and
    /// that no two overlap (what the unsafe writes of [`forward`] rely on), and the most
    /// columns one has.
    #[track_caller]
    fn chunks(&self, g: &impl Columns) -> (Vec<Chunk>, usize) {
        let chunks = g.chunks();
        let mut sorted = chunks.clone();
        sorted.sort_unstable();
        for &(n, first, cols) in &sorted {
            let end = first.checked_add(cols);
            assert!(
                n < self.batch && end.is_some_and(|end| end <= self.out_len),
                "conv-kernels: chunk {:?} outside {} items of {} columns",
                (n, first, cols),
                self.batch,
                self.out_len
            );
        }
        for pair in sorted.windows(2) {
            let ((n0, first0, cols0), (n1, first1, _)) = (pair[0], pair[1]);
            assert!(
                n0 != n1 || first0 + cols0 <= first1,
                "conv-kernels: chunks {:?} and {:?} overlap",
                pair[0],
                pair[1]
            );
        }
        let most = chunks.iter().map(|&(_, _, cols)| cols).max().unwrap_or(0);
        product("scratch sizes", &[self.patch, most]);
        (chunks, most)
    }
}

/// Columns per chunk for im2col columns of `patch_len` values (positive): `cols` stays near
/// 2^18 values (1 MiB of f32, half of one core's L2 cache on the machines measured), rounded
/// down to whole multiples of `unit` (at least one unit).
pub fn chunk_columns(patch_len: usize, unit: usize) -> usize {
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

    /// # Panics
    /// If the geometry is not [valid](Geometry::is_valid).
    fn out_len(&self) -> usize {
        assert!(self.is_valid(), "conv-kernels: invalid geometry {self:?}");
        self.output().iter().product()
    }

    /// Whole output rows (the `W_out` voxels of one `(n, d, h)`) per chunk.
    ///
    /// # Panics
    /// If the geometry is not [valid](Geometry::is_valid).
    fn chunks(&self) -> Vec<Chunk> {
        assert!(self.is_valid(), "conv-kernels: invalid geometry {self:?}");
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
///
/// # Panics
/// If a slice's length does not match `g`, or `g`'s chunks overlap or leave the output (for a
/// [`Geometry`]: unless it is [valid](Geometry::is_valid)).
pub fn forward<T: Element>(x: &[T], w: &[T], g: &impl Columns) -> Vec<T> {
    let sizes = Sizes::of(g);
    let (in_len, out_len, patch) = (sizes.in_len, sizes.out_len, sizes.patch);
    let (batch, c_in, c_out) = (sizes.batch, sizes.c_in, sizes.c_out);
    sizes.check("input", x.len(), &[batch, c_in, in_len]);
    sizes.check("kernel", w.len(), &[c_out, patch]);
    let (chunks, max_cols) = sizes.chunks(g);
    let mut out = vec![T::ZERO; product("output sizes", &[batch, c_out, out_len])];
    let dst = SharedMut(out.as_mut_ptr());
    chunks.into_par_iter().for_each_init(
        || pooled_vec::<T>(patch * max_cols),
        |cols, chunk| {
            let (n, first, nc) = chunk;
            let cols = &mut cols[..patch * nc];
            g.fill(cols, &x[n * c_in * in_len..], chunk);
            // SAFETY: `out` outlives the parallel loop; this task writes only columns
            // `first .. first + nc` of the `C_out` rows of item `n` (row stride `out_len`), which
            // no other chunk covers and which lie in `out` (both checked by `Sizes::chunks`);
            // `w` (`C_out x patch`, checked) and `cols` (`patch x nc`) are read-only with the
            // strides given.
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

/// Gradient of `sum(grad_out * conv(x, w))` with respect to `w`: shape `(C_out, C_in, taps)`,
/// `x` `(N, C_in, in_len)` and `grad_out` `(N, C_out, out_len)` as in [`forward`].
///
/// # Panics
/// As [`forward`].
pub fn grad_weight<T: Element>(x: &[T], grad_out: &[T], g: &impl Columns) -> Vec<T> {
    let sizes = Sizes::of(g);
    let (in_len, out_len, patch) = (sizes.in_len, sizes.out_len, sizes.patch);
    let (batch, c_in, c_out) = (sizes.batch, sizes.c_in, sizes.c_out);
    sizes.check("input", x.len(), &[batch, c_in, in_len]);
    sizes.check("output gradient", grad_out.len(), &[batch, c_out, out_len]);
    let size = product("kernel sizes", &[c_out, patch]);
    let (chunks, max_cols) = sizes.chunks(g);
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
                // SAFETY: all pointers cover the ranges implied by the dimensions and strides:
                // `acc` is `C_out x patch`, `go` holds the `C_out` rows (`out_len` apart) of
                // columns `first .. first + nc <= out_len` of item `n < N` of the checked
                // `grad_out`, `chunk_cols` is `patch x nc`.
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
///
/// # Panics
/// If `w` is shorter than `C_out x C_in x taps`.
pub fn flipped_transposed<T: Element>(w: &[T], g: &impl Columns) -> Vec<T> {
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
///
/// # Panics
/// Unless `g` is [valid](Geometry::is_valid) and the slices have its lengths.
pub fn grad_input<T: Element>(grad_out: &[T], w: &[T], g: &Geometry) -> Vec<T> {
    assert_valid(
        g,
        [
            ("output gradient", grad_out.len(), g.output_len()),
            ("kernel", w.len(), g.kernel_len()),
        ],
    );
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

#[cfg(test)]
mod tests {
    use super::*;

    /// A 2D geometry whose kernel does not fit Winograd (5 taps, stride 2).
    const G: Geometry = Geometry {
        batch: 2,
        c_in: 3,
        c_out: 4,
        input: [1, 9, 11],
        kernel: [1, 5, 5],
        padding: [0, 2, 2],
        stride: 2,
    };

    /// The convolution and its two gradients in f64 by their definitions, one output at a time.
    fn direct(x: &[f64], w: &[f64], go: &[f64], g: &Geometry) -> [Vec<f64>; 3] {
        let ([_, h, wd], [_, kh, kw], [_, ph, pw]) = (g.input, g.kernel, g.padding);
        let [_, ho, wo] = g.output();
        let mut y = vec![0.0; g.output_len()];
        let mut gx = vec![0.0; g.input_len()];
        let mut gw = vec![0.0; g.kernel_len()];
        for n in 0..g.batch {
            for o in 0..g.c_out {
                for (i, j) in (0..ho).flat_map(|i| (0..wo).map(move |j| (i, j))) {
                    let at = ((n * g.c_out + o) * ho + i) * wo + j;
                    for (c, t) in (0..g.c_in).flat_map(|c| (0..kh * kw).map(move |t| (c, t))) {
                        let (r, s) = (
                            (g.stride * i + t / kw) as isize,
                            (g.stride * j + t % kw) as isize,
                        );
                        let (r, s) = (r - ph as isize, s - pw as isize);
                        if r < 0 || s < 0 || r >= h as isize || s >= wd as isize {
                            continue;
                        }
                        let xi = ((n * g.c_in + c) * h + r as usize) * wd + s as usize;
                        let wi = (o * g.c_in + c) * kh * kw + t;
                        y[at] += x[xi] * w[wi];
                        gx[xi] += go[at] * w[wi];
                        gw[wi] += go[at] * x[xi];
                    }
                }
            }
        }
        [y, gx, gw]
    }

    #[test]
    fn the_three_passes_equal_the_direct_sums_with_stride_and_padding() {
        let values = |n: usize, k: f64| (0..n).map(|i| (i as f64 * k).sin()).collect::<Vec<_>>();
        let (x, w, go) = (
            values(G.input_len(), 0.37),
            values(G.kernel_len(), 0.11),
            values(G.output_len(), 0.23),
        );
        let ours = [
            forward(&x, &w, &G),
            grad_input(&go, &w, &G),
            grad_weight(&x, &go, &G),
        ];
        for (pass, (a, b)) in ours.iter().zip(direct(&x, &w, &go, &G)).enumerate() {
            assert_eq!(a.len(), b.len(), "pass {pass}");
            assert!(
                a.iter().zip(&b).all(|(a, b)| (a - b).abs() < 1e-12),
                "pass {pass}"
            );
        }
    }

    #[test]
    #[should_panic(expected = "kernel of 299 values")]
    fn a_short_kernel_is_refused() {
        let x = vec![0f32; G.input_len()];
        forward(&x, &vec![0f32; G.kernel_len() - 1], &G);
    }

    #[test]
    #[should_panic(expected = "invalid geometry")]
    fn an_invalid_geometry_is_refused() {
        let g = Geometry {
            input: [1, 9, 3],
            padding: [0; 3],
            ..G
        };
        forward(&vec![0f32; g.input_len()], &vec![0f32; g.kernel_len()], &g);
    }

    /// [`G`] with its chunks replaced by `chunks`.
    struct Chunked(Vec<Chunk>);

    impl Columns for Chunked {
        fn batch(&self) -> usize {
            G.batch()
        }
        fn c_in(&self) -> usize {
            G.c_in()
        }
        fn c_out(&self) -> usize {
            G.c_out()
        }
        fn taps(&self) -> usize {
            G.taps()
        }
        fn in_len(&self) -> usize {
            G.in_len()
        }
        fn out_len(&self) -> usize {
            G.out_len()
        }
        fn chunks(&self) -> Vec<Chunk> {
            self.0.clone()
        }
        fn fill<T: Element>(&self, cols: &mut [T], x_n: &[T], chunk: Chunk) {
            G.fill(cols, x_n, chunk)
        }
    }

    #[test]
    fn chunks_that_overlap_or_leave_the_output_are_refused() {
        let (x, w) = (vec![1f32; G.input_len()], vec![1f32; G.kernel_len()]);
        // G's output is 5 x 6 = 30 columns per item.
        let fine = Chunked(vec![(0, 0, 30), (1, 12, 18), (1, 0, 12)]);
        assert_eq!(forward(&x, &w, &fine), forward(&x, &w, &G));
        for chunks in [
            vec![(0, 0, 30), (0, 29, 1)],
            vec![(1, 24, 7)],
            vec![(2, 0, 6)],
        ] {
            let bad = Chunked(chunks.clone());
            let run = std::panic::catch_unwind(|| forward(&x, &w, &bad));
            assert!(run.is_err(), "{chunks:?}");
        }
    }
}

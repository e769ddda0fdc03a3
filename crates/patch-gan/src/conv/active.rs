//! The submanifold convolution on active sites: im2col columns gathered through the sites'
//! neighbour table, then the same `gemm` kernels as the dense convolution.

use std::sync::Arc;

use conv_kernels::im2col::{self, chunk_columns};
use conv_kernels::{Chunk, Columns, Element};

use crate::active::{ActiveSites, NO_SITE};

/// A convolution from `c_in` to `c_out` channels on the active sites: input and output
/// `(1, C, M, 1, 1)`, kernel `(C_out, C_in, k, k, k)` with `k` the sites' kernel.
#[derive(Debug, Clone)]
pub(crate) struct ActiveGeometry {
    pub c_in: usize,
    pub c_out: usize,
    pub sites: Arc<ActiveSites>,
}

/// Columns per chunk are rounded to this many, the width of `gemm`'s f32 micro-kernels.
const COLUMN_UNIT: usize = 8;

impl Columns for ActiveGeometry {
    fn batch(&self) -> usize {
        1
    }

    fn c_in(&self) -> usize {
        self.c_in
    }

    fn c_out(&self) -> usize {
        self.c_out
    }

    fn taps(&self) -> usize {
        self.sites.taps()
    }

    fn in_len(&self) -> usize {
        self.sites.len()
    }

    fn out_len(&self) -> usize {
        self.sites.len()
    }

    fn chunks(&self) -> Vec<Chunk> {
        let m = self.sites.len();
        let per_chunk = chunk_columns(self.patch_len(), COLUMN_UNIT);
        (0..m)
            .step_by(per_chunk)
            .map(|first| (0, first, per_chunk.min(m - first)))
            .collect()
    }

    /// Tap by tap, run by run, and every input channel for each run: the runs are the same for
    /// all channels, so each is found and decoded once per chunk, not once per channel (finding
    /// a chunk's first run per row was 30% of this function's time in `tiny`'s training).
    fn fill<T: Element>(&self, cols: &mut [T], x: &[T], (_, first, len): Chunk) {
        let (m, taps, end) = (self.sites.len(), self.taps(), first + len);
        for tap in 0..taps {
            let runs = self.sites.runs(tap);
            let mut k = runs.partition_point(|run| run.end() <= first);
            while let Some(run) = runs.get(k).filter(|run| (run.start as usize) < end) {
                let (start, source) = (run.start as usize, run.source as usize);
                let (lo, hi) = (start.max(first), run.end().min(end));
                for c in 0..self.c_in {
                    let seg = &mut cols[(c * taps + tap) * len..][lo - first..hi - first];
                    if run.source == NO_SITE {
                        seg.fill(T::ZERO);
                    } else {
                        let from = c * m + source + lo - start;
                        seg.copy_from_slice(&x[from..from + seg.len()]);
                    }
                }
                k += 1;
            }
        }
    }
}

/// Gradient of `sum(grad_out * conv(x, w))` with respect to `x`. The neighbour table is
/// symmetric (tap `t` of site `j` is `i` exactly when tap `taps - 1 - t` of `i` is `j`), so the
/// transposed convolution is a convolution on the same sites with the kernel flipped and its
/// channel axes swapped.
pub(crate) fn grad_input<T: Element>(grad_out: &[T], w: &[T], g: &ActiveGeometry) -> Vec<T> {
    let transposed = ActiveGeometry {
        c_in: g.c_out,
        c_out: g.c_in,
        sites: Arc::clone(&g.sites),
    };
    im2col::forward(grad_out, &im2col::flipped_transposed(w, g), &transposed)
}

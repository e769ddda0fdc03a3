//! Fused CPU ops for the element-wise work between convolutions: LeakyReLU (and its bias add),
//! and BatchNorm with LeakyReLU, forward and backward each in one threaded sweep.
//!
//! Built from candle's own ops, LeakyReLU is five passes over the tensor (`zeros_like`,
//! `maximum`, `minimum`, `affine`, `add`), each allocating, single-threaded, with a backward of
//! as many again; BatchNorm is a dozen. At the generators' sizes (32 channels x 40^3 voxels =
//! 8 MB per tensor) these passes, not the convolutions, were most of a training step. Here each
//! layer's element-wise work is one read and one write of its tensor in the forward pass and two
//! reads and one write in the backward pass, split over rayon's threads in fixed chunks (per
//! channel where a sum is taken, summed in f64), so results do not depend on the thread count.

mod batch_norm;
mod channel_sum;
mod leaky;

pub(crate) use batch_norm::{batch_norm_act, NormStats};
pub(crate) use leaky::leaky_grad;
pub use leaky::{bias_leaky_relu, leaky_relu};

/// Elements per parallel task of the element-wise kernels: large enough that rayon's overhead
/// vanishes, small enough that two threads share the work evenly.
const CHUNK: usize = 1 << 14;

/// The `(channels, plane)` split of an `(N, C, ...)` tensor: `C` and the product of the axes after it.
fn channels_and_plane(dims: &[usize]) -> (usize, usize) {
    let channels = dims.get(1).copied().unwrap_or(1);
    (channels, dims.iter().skip(2).product())
}

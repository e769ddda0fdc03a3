//! Conv3d from candle's own conv2d: the path for devices without our CPU kernel (CUDA).

use candle_core::Tensor;
use conv_kernels::Geometry;

use crate::error::{invalid, Result};

/// `conv3d` as one conv2d over depth slices: output depth `z` reads the input slices
/// `z * stride + kd` (of the depth-padded input) for every depth tap `kd`; those are stacked
/// along the channels, and the kernel's depth taps likewise, so one conv2d of `kd * C_in`
/// input channels over a batch of `N * D_out` slices computes it. Built from candle ops only,
/// so it runs and differentiates on every device candle's conv2d supports. `g` comes from
/// `geometry`.
///
/// Written for memory, because candle keeps every intermediate of the graph until the backward
/// pass: the input is padded along depth and laid out `(N, D, C, H, W)` once, the taps are
/// views of it (stride 1) and one stacked copy, and there is one conv2d output: about 7 tensors
/// of the input's size per layer (the stacked copy counts 3), where a sum of per-tap conv2ds
/// kept 13.
///
/// With a stride that leaves a remainder the input is also padded in height and width here and
/// cut to the extent the strided taps read, so candle's conv2d runs without padding on an input
/// whose size fits its stride exactly: its backward pass (a transposed convolution without
/// output padding in candle 0.11) would otherwise give the input gradient the wrong size.
pub(crate) fn conv3d_by_slices(xs: &Tensor, kernel: &Tensor, g: &Geometry) -> Result<Tensor> {
    let [d_out, h_out, w_out] = g.output();
    // `conv3d` gives every axis the same padding.
    let (n, p, s) = (g.batch, g.padding[0], g.stride);
    let [kd, kh, kw] = g.kernel;
    let [_, h, w] = g.input;
    let exact = |size: usize, out: usize, k: usize| (out - 1) * s + k == size + 2 * p;
    let (mut input, mut plane_padding) = (xs.pad_with_zeros(2, p, p)?, p);
    if !(exact(h, h_out, kh) && exact(w, w_out, kw)) {
        input = input
            .pad_with_zeros(3, p, p)?
            .pad_with_zeros(4, p, p)?
            .narrow(3, 0, (h_out - 1) * s + kh)?
            .narrow(4, 0, (w_out - 1) * s + kw)?;
        plane_padding = 0;
    }
    // (N, C_in, D', H', W') -> (N, D', C_in, H', W')
    let input = input.permute((0, 2, 1, 3, 4))?.contiguous()?;
    let (h_in, w_in) = (input.dim(3)?, input.dim(4)?);
    let taps = (0..kd)
        .map(|tap| -> Result<Tensor> {
            Ok(if s == 1 {
                input.narrow(1, tap, d_out)?
            } else {
                let depths: Vec<u32> = (0..d_out).map(|z| (tap + z * s) as u32).collect();
                input.index_select(&Tensor::from_vec(depths, d_out, xs.device())?, 1)?
            })
        })
        .collect::<Result<Vec<_>>>()?;
    if taps.is_empty() {
        return Err(invalid("kernel", "has no depth taps"));
    }
    // (N, D_out, kd * C_in, H', W') -> (N * D_out, kd * C_in, H', W')
    let stacked = Tensor::cat(&taps, 2)?.reshape((n * d_out, kd * g.c_in, h_in, w_in))?;
    // (C_out, C_in, kd, kh, kw) -> (C_out, kd * C_in, kh, kw), taps in the order stacked.
    let kernel =
        kernel
            .permute((0, 2, 1, 3, 4))?
            .contiguous()?
            .reshape((g.c_out, kd * g.c_in, kh, kw))?;
    let out = stacked.conv2d(&kernel, plane_padding, s, 1, 1)?;
    Ok(out
        .reshape((n, d_out, g.c_out, h_out, w_out))?
        .permute((0, 2, 1, 3, 4))?
        .contiguous()?)
}

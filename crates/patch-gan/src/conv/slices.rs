//! Conv3d from candle's own conv2d: the path for devices without our CPU kernel (CUDA).

use candle_core::Tensor;
use conv_kernels::Geometry;

use crate::error::{invalid, Result};

/// `conv3d` as a sum over the kernel's depth taps of conv2d over depth slices: for tap `kd`,
/// the input slices `kd, kd + stride, ...` (of the depth-padded input) are folded into the batch
/// and convolved with the kernel's slice `kd`. Built from candle ops only, so it runs and
/// differentiates on every device candle's conv2d supports. `g` comes from `geometry`.
///
/// The input is padded here on every axis and cut to the extent the strided taps read, so
/// candle's conv2d runs without padding on an input whose size fits its stride exactly: its
/// backward pass (a transposed convolution without output padding in candle 0.11) would
/// otherwise give the input gradient the wrong size when the stride leaves a remainder.
pub(crate) fn conv3d_by_slices(xs: &Tensor, kernel: &Tensor, g: &Geometry) -> Result<Tensor> {
    let [d_out, h_out, w_out] = g.output();
    // `conv3d` gives every axis the same padding.
    let (n, p, s) = (g.batch, g.padding[0], g.stride);
    let (kh, kw) = (g.kernel[1], g.kernel[2]);
    let padded = xs
        .pad_with_zeros(2, p, p)?
        .pad_with_zeros(3, p, p)?
        .pad_with_zeros(4, p, p)?
        .narrow(3, 0, (h_out - 1) * s + kh)?
        .narrow(4, 0, (w_out - 1) * s + kw)?
        .contiguous()?;
    let (h, w) = (padded.dim(3)?, padded.dim(4)?);
    let mut sum: Option<Tensor> = None;
    for kd in 0..g.kernel[0] {
        let depths: Vec<u32> = (0..d_out).map(|z| (kd + z * s) as u32).collect();
        let index = Tensor::from_vec(depths, d_out, xs.device())?;
        // (N, C_in, D_out, H, W) -> (N * D_out, C_in, H, W)
        let slices = padded.index_select(&index, 2)?.permute((0, 2, 1, 3, 4))?;
        let slices = slices.contiguous()?.reshape((n * d_out, g.c_in, h, w))?;
        let taps = kernel.narrow(2, kd, 1)?.squeeze(2)?.contiguous()?;
        let part = slices.conv2d(&taps, 0, s, 1, 1)?;
        sum = Some(match sum {
            None => part,
            Some(acc) => (acc + part)?,
        });
    }
    let out = sum.ok_or_else(|| invalid("kernel", "has no depth taps"))?;
    Ok(out
        .reshape((n, d_out, g.c_out, h_out, w_out))?
        .permute((0, 2, 1, 3, 4))?
        .contiguous()?)
}

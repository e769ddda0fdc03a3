//! Resampling between resolutions over the same box: trilinear between cell centres, applied as
//! three separable interpolation matrices, so it runs on any device and is differentiable.

use candle_core::{Device, Tensor};

use crate::error::{invalid, Result};
use crate::grid::GridDims;
use crate::sample::AxisLerp;
use crate::volume::RadianceVolume;

/// Returns the `(n_out, n_in)` matrix that linearly interpolates a cell-centred axis of `n_in`
/// cells at the centres of `n_out` cells over the same extent (edge-clamped).
fn interpolation_matrix(n_in: usize, n_out: usize, device: &Device) -> Result<Tensor> {
    let mut m = vec![0f32; n_out * n_in];
    let ratio = n_in as f32 / n_out as f32;
    for (j, row) in m.chunks_mut(n_in).enumerate() {
        // Centre of output cell j, in input index coordinates.
        let lerp = AxisLerp::new((j as f32 + 0.5) * ratio - 0.5, n_in);
        row[lerp.i0] += 1.0 - lerp.t;
        row[lerp.i1] += lerp.t;
    }
    Ok(Tensor::from_vec(m, (n_out, n_in), device)?)
}

/// Interpolates dimension `dim` of `x` from its size to `n_out`.
fn resample_dim(x: &Tensor, dim: usize, n_out: usize) -> Result<Tensor> {
    let n_in = x.dim(dim)?;
    if n_in == n_out {
        return Ok(x.clone());
    }
    let m = interpolation_matrix(n_in, n_out, x.device())?.to_dtype(x.dtype())?;
    let last = x.rank() - 1;
    let moved = x.transpose(dim, last)?.contiguous()?;
    let mut shape = moved.dims().to_vec();
    let rows = moved.elem_count() / n_in;
    let out = moved.reshape((rows, n_in))?.matmul(&m.t()?)?;
    shape[last] = n_out;
    Ok(out.reshape(shape)?.transpose(dim, last)?.contiguous()?)
}

/// Trilinearly resamples the last three dimensions `(D, H, W)` of a tensor of any rank >= 3 (for
/// example `(C, D, H, W)` or `(N, C, D, H, W)`) to `dims`, treating both grids as cell-centred
/// over the same box.
///
/// Constant fields stay constant. Linear fields stay exact when down-sampling (every new centre
/// lies between old centres) and, when up-sampling, at every new centre inside the hull of the
/// old centres; the new centres beyond it take the clamped edge value, the convention of
/// docs/architecture.md. There is no low-pass pre-filter: when down-sampling by more than 2 the result can
/// alias (the pyramid's steps of 4/3 are well below that).
///
/// ```
/// use candle_core::{Device, Tensor};
/// use radiance_volume::{resample_tensor, GridDims};
/// let x = Tensor::ones((4, 30, 30, 30), candle_core::DType::F32, &Device::Cpu)?;
/// let y = resample_tensor(&x, GridDims::cube(40))?;
/// assert_eq!(y.dims(), &[4, 40, 40, 40]);
/// # Ok::<(), radiance_volume::Error>(())
/// ```
pub fn resample_tensor(x: &Tensor, dims: GridDims) -> Result<Tensor> {
    dims.validate()?;
    let rank = x.rank();
    if rank < 3 {
        return Err(invalid(
            "x",
            format!(
                "expected at least 3 dimensions (.., D, H, W), got {:?}",
                x.shape()
            ),
        ));
    }
    let x = resample_dim(x, rank - 1, dims.w)?;
    let x = resample_dim(&x, rank - 2, dims.h)?;
    resample_dim(&x, rank - 3, dims.d)
}

impl RadianceVolume {
    /// Resamples the volume to another resolution over the same box (see [`resample_tensor`]).
    pub fn resample(&self, dims: GridDims) -> Result<Self> {
        self.with_tensor(resample_tensor(self.tensor(), dims)?)
    }

    /// Scales the resolution by `factor` per axis (rounded, at least 1 cell), e.g. the pyramid's
    /// 4/3 up and 3/4 down.
    pub fn rescale(&self, factor: f32) -> Result<Self> {
        if !(factor.is_finite() && factor > 0.0) {
            return Err(invalid(
                "factor",
                format!("expected a finite factor > 0, got {factor}"),
            ));
        }
        let scale = |n: usize| ((n as f32 * factor).round() as usize).max(1);
        let d = self.dims();
        self.resample(GridDims::new(scale(d.d), scale(d.h), scale(d.w)))
    }
}

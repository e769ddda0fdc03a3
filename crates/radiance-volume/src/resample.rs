//! Resampling between resolutions over the same box: trilinear between cell centres, separable
//! and differentiable: on the CPU (f32) three passes of two-tap lerps (`resample_op`), on other
//! devices three interpolation matrices.

use std::ops::Range;

use candle_core::{DType, Device, Tensor};
use rayon::prelude::*;

use crate::activation::Activation;
use crate::error::{invalid, Result};
use crate::grid::{GridDims, VoxelGrid};
use crate::resample_op::Resample;
use crate::sample::AxisLerp;
use crate::source::{check_channels, VolumeSource};
use crate::volume::RadianceVolume;
use crate::VoxelRange;

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
/// use candle_core::{DType, Device, Tensor};
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
    if x.device().is_cpu() && x.dtype() == DType::F32 {
        let op = Resample {
            to: [dims.d, dims.h, dims.w],
        };
        return Ok(x.contiguous()?.apply_op1(op)?);
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

/// A volume resampled to another grid over the same box, computed block by block when read
/// ([`VolumeSource`]): every cell holds the trilinear interpolation of the volume's cell centres
/// at its own centre, with [`RadianceVolume::resample`]'s weights (each cell computed alone, so
/// that it gets the same bits in blocks of any shape and a file streamed block by block is the
/// file of the whole; the same bits as [`RadianceVolume::resample`] of an f32 volume on the
/// CPU, which lerps in the same order, and the same values to float rounding elsewhere), and, with
/// [`Resampled::with_density_activation`], channel 0 is then mapped through the activation's
/// density (post-activated density: interpolate raw density, then activate).
///
/// A block reads only the cells of the volume it interpolates from, so writers can stream a
/// volume 27 times larger than the source (`factor` 3) through a small buffer.
///
/// ```
/// use radiance_volume::{Aabb, Activation, GridDims, RadianceVolume, VoxelRange, Resampled, VolumeSource};
/// let v = RadianceVolume::from_fn(GridDims::cube(4), Aabb::CUBE, 4, |p, out| {
///     out.copy_from_slice(&[p.x, 0.5, 0.5, 0.5]);
/// })?;
/// let fine = Resampled::finer(v, 3)?.with_density_activation(Activation::default());
/// assert_eq!(fine.dims(), GridDims::cube(12));
/// // Fine cell x = 4 sits on the centre of coarse cell 1 (x = -0.25): softplus(-0.25).
/// let sigma = fine.read_block(0..1, &VoxelRange { z: 0..1, y: 0..1, x: 4..5 })?[0];
/// assert!((sigma - (1.0 + (-0.25f32).exp()).ln()).abs() < 1e-6);
/// # Ok::<(), radiance_volume::Error>(())
/// ```
#[derive(Debug, Clone)]
pub struct Resampled {
    volume: RadianceVolume,
    dims: GridDims,
    density: Option<Activation>,
}

impl Resampled {
    /// `volume` on a grid of `dims` cells over its box (a volume's clone shares its memory).
    pub fn new(volume: RadianceVolume, dims: GridDims) -> Result<Self> {
        dims.validate()?;
        Ok(Self {
            volume,
            dims,
            density: None,
        })
    }

    /// `volume` on a grid `factor` times finer along every axis (`factor >= 1`).
    pub fn finer(volume: RadianceVolume, factor: usize) -> Result<Self> {
        let d = volume.dims();
        Self::new(
            volume,
            GridDims::new(d.d * factor, d.h * factor, d.w * factor),
        )
    }

    /// Maps interpolated channel 0 (raw density) through `activation`'s density.
    #[must_use]
    pub fn with_density_activation(self, activation: Activation) -> Self {
        Self {
            density: Some(activation),
            ..self
        }
    }

    /// Computes the whole volume at once (as much memory as its cells need).
    pub fn to_volume(&self) -> Result<RadianceVolume> {
        let values = self.read_block(0..self.channel_count(), &VoxelRange::all(self.dims))?;
        let d = self.dims;
        let shape = (self.channel_count(), d.d, d.h, d.w);
        let data = Tensor::from_vec(values, shape, self.volume.tensor().device())?;
        self.volume.with_tensor(data)
    }
}

impl VolumeSource for Resampled {
    fn grid(&self) -> VoxelGrid {
        VoxelGrid {
            aabb: self.volume.aabb(),
            dims: self.dims,
        }
    }

    fn channel_names(&self) -> &[String] {
        self.volume.channel_names()
    }

    fn read_block(&self, channels: Range<usize>, region: &VoxelRange) -> Result<Vec<f32>> {
        region.validate(self.dims)?;
        check_channels(&channels, self.channel_count())?;
        let coarse = self.volume.dims();
        let lerps = [
            axis_lerps(coarse.w, self.dims.w, region.x.clone()),
            axis_lerps(coarse.h, self.dims.h, region.y.clone()),
            axis_lerps(coarse.d, self.dims.d, region.z.clone()),
        ];
        let out_dims = region.dims();
        let plane = out_dims.h * out_dims.w;
        let mut out = vec![0f32; channels.len() * out_dims.voxel_count()];
        self.volume.with_values(|values| {
            out.par_chunks_mut(plane).enumerate().for_each(|(i, dst)| {
                let (c, z) = (channels.start + i / out_dims.d, i % out_dims.d);
                let channel = &values[c * coarse.voxel_count()..][..coarse.voxel_count()];
                interpolate_plane(channel, coarse, &lerps, z, dst);
            });
        })?;
        if let (Some(activation), 0) = (self.density, channels.start) {
            let n = out_dims.voxel_count();
            let sigma = Tensor::from_slice(&out[..n], n, &Device::Cpu)?;
            let sigma: Vec<f32> = activation.apply_density(&sigma)?.to_vec1()?;
            out[..n].copy_from_slice(&sigma);
        }
        Ok(out)
    }
}

/// The trilinear taps of output cells `rows` on an axis of `n_out` cells over `n_in` input
/// cells (cell-centred, edge-clamped): the same weights as [`interpolation_matrix`]'s rows.
pub(crate) fn axis_lerps(n_in: usize, n_out: usize, rows: Range<usize>) -> Vec<AxisLerp> {
    let ratio = n_in as f32 / n_out as f32;
    rows.map(|j| AxisLerp::new((j as f32 + 0.5) * ratio - 0.5, n_in))
        .collect()
}

/// `a (1 - t) + b t`, and exactly `a` at `t = 0` (a cell on an input centre is a copy of it,
/// even beside an infinity).
pub(crate) fn lerp(a: f32, b: f32, t: f32) -> f32 {
    if t == 0.0 {
        a
    } else {
        a * (1.0 - t) + b * t
    }
}

/// Fills `dst` (one output plane, `(y, x)` row-major) with the interpolation of one channel
/// `(D, H, W)` of `dims` at output plane `z` of the block whose taps `[x, y, z]` are `lerps`:
/// along x first, then y, then z, each output value computed alone in that order, so a voxel
/// gets the same bits in a block of any shape.
fn interpolate_plane(
    channel: &[f32],
    dims: GridDims,
    [lx, ly, lz]: &[Vec<AxisLerp>; 3],
    z: usize,
    dst: &mut [f32],
) {
    let tz = lz[z];
    let along_x = |zi: usize, yi: usize, l: &AxisLerp| {
        let row = &channel[dims.index(zi, yi, 0)..][..dims.w];
        lerp(row[l.i0], row[l.i1], l.t)
    };
    for (ty, out_row) in ly.iter().zip(dst.chunks_exact_mut(lx.len())) {
        for (tx, out) in lx.iter().zip(out_row) {
            let at_z = |zi: usize| lerp(along_x(zi, ty.i0, tx), along_x(zi, ty.i1, tx), ty.t);
            *out = lerp(at_z(tz.i0), at_z(tz.i1), tz.t);
        }
    }
}

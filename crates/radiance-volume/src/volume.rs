//! The [`RadianceVolume`] type: a `(C, D, H, W)` tensor, its world box and its channel names.

use candle_core::{DType, Device, Storage, Tensor};
use glam::Vec3;
use rayon::prelude::*;

use crate::activation::Activation;
use crate::error::{invalid, Result};
use crate::grid::{Aabb, GridDims, VoxelGrid};
use crate::sample::sample_into;
use crate::source::VolumeSource;

/// The names of the four physical channels every volume starts with.
pub const BASE_CHANNELS: [&str; 4] = ["sigma", "r", "g", "b"];

/// A voxel radiance volume: an f32 tensor `(C, D, H, W)` (D along z, H along y, W along x) with
/// density sigma in channel 0, RGB in channels 1..4 and optional feature channels after, laid
/// cell-centred over a world box (default `[-1, 1]^3`).
///
/// A *physical* volume holds sigma >= 0 (1/world-length) and colour in [0, 1]; use
/// [`RadianceVolume::from_raw`] to get one from network output.
///
/// ```
/// use radiance_volume::{Aabb, GridDims, RadianceVolume};
/// use glam::Vec3;
/// // A ball of density 5 and a colour gradient along x.
/// let v = RadianceVolume::from_fn(GridDims::cube(16), Aabb::CUBE, 4, |p, out| {
///     out[0] = if p.length() < 0.5 { 5.0 } else { 0.0 };
///     out[1..4].copy_from_slice(&[p.x * 0.5 + 0.5, 0.2, 0.8]);
/// })?;
/// assert_eq!(v.dims(), GridDims::cube(16));
/// let s = v.sample(Vec3::new(0.0, 0.0, 0.0))?;
/// assert!(s[0] > 0.0 && (s[1] - 0.5).abs() < 1e-6);
/// # Ok::<(), radiance_volume::Error>(())
/// ```
#[derive(Debug, Clone)]
pub struct RadianceVolume {
    data: Tensor,
    grid: VoxelGrid,
    channel_names: Vec<String>,
}

impl RadianceVolume {
    /// Wraps a `(C, D, H, W)` tensor (C >= 4, every size >= 1) over `aabb`, converting it to
    /// contiguous f32. Channels get the default names (`sigma, r, g, b, f0, f1, ...`).
    pub fn new(data: Tensor, aabb: Aabb) -> Result<Self> {
        let (channels, d, h, w) = data.dims4().map_err(|_| {
            invalid(
                "data",
                format!(
                    "expected a (C, D, H, W) tensor, got shape {:?}",
                    data.shape()
                ),
            )
        })?;
        if channels < 4 {
            return Err(invalid(
                "data",
                format!("expected at least 4 channels (sigma, r, g, b), got {channels}"),
            ));
        }
        let grid = VoxelGrid::new(aabb, GridDims::new(d, h, w))?;
        let data = data.to_dtype(DType::F32)?.contiguous()?;
        Ok(Self {
            data,
            grid,
            channel_names: default_channel_names(channels),
        })
    }

    /// Replaces the channel names; there must be one per channel, all distinct and non-empty.
    pub fn with_channel_names<S: Into<String>>(
        self,
        names: impl IntoIterator<Item = S>,
    ) -> Result<Self> {
        let names: Vec<String> = names.into_iter().map(Into::into).collect();
        validate_channel_names(&names, self.channel_count())?;
        Ok(Self {
            channel_names: names,
            ..self
        })
    }

    /// Builds a volume on the CPU by evaluating `f(world_point, channels_out)` at every cell
    /// centre (in parallel).
    pub fn from_fn(
        dims: GridDims,
        aabb: Aabb,
        channels: usize,
        f: impl Fn(Vec3, &mut [f32]) + Sync,
    ) -> Result<Self> {
        let grid = VoxelGrid::new(aabb, dims)?;
        if channels < 4 {
            return Err(invalid(
                "channels",
                format!("expected at least 4 channels (sigma, r, g, b), got {channels}"),
            ));
        }
        let voxels = dims.voxel_count();
        // Evaluate voxel-major (one closure call fills all channels), then transpose to
        // channel-major, the tensor layout.
        let mut interleaved = vec![0f32; voxels * channels];
        interleaved
            .par_chunks_mut(channels)
            .enumerate()
            .for_each(|(i, out)| {
                let (z, rest) = (i / (dims.h * dims.w), i % (dims.h * dims.w));
                f(grid.cell_center(z, rest / dims.w, rest % dims.w), out);
            });
        let mut planar = vec![0f32; voxels * channels];
        for (i, vals) in interleaved.chunks(channels).enumerate() {
            for (c, &v) in vals.iter().enumerate() {
                planar[c * voxels + i] = v;
            }
        }
        let data = Tensor::from_vec(planar, (channels, dims.d, dims.h, dims.w), &Device::Cpu)?;
        Self::new(data, aabb)
    }

    /// Builds a physical volume from raw network output `(C, D, H, W)` through `activation`.
    pub fn from_raw(raw: &Tensor, aabb: Aabb, activation: &Activation) -> Result<Self> {
        Self::new(activation.apply(raw)?, aabb)
    }

    /// Returns the `(C, D, H, W)` f32 tensor.
    #[must_use]
    pub fn tensor(&self) -> &Tensor {
        &self.data
    }

    /// Consumes the volume and returns its tensor.
    #[must_use]
    pub fn into_tensor(self) -> Tensor {
        self.data
    }

    /// Returns the grid (world box and sizes).
    #[must_use]
    pub fn grid(&self) -> &VoxelGrid {
        &self.grid
    }

    /// Returns the world box.
    #[must_use]
    pub fn aabb(&self) -> Aabb {
        self.grid.aabb
    }

    /// Returns the grid sizes.
    #[must_use]
    pub fn dims(&self) -> GridDims {
        self.grid.dims
    }

    /// Returns the number of channels C.
    #[must_use]
    pub fn channel_count(&self) -> usize {
        self.channel_names.len()
    }

    /// Returns the channel names.
    #[must_use]
    pub fn channel_names(&self) -> &[String] {
        &self.channel_names
    }

    /// Returns the density channel, `(1, D, H, W)`.
    pub fn density(&self) -> Result<Tensor> {
        Ok(self.data.narrow(0, 0, 1)?)
    }

    /// Returns the colour channels, `(3, D, H, W)`.
    pub fn rgb(&self) -> Result<Tensor> {
        Ok(self.data.narrow(0, 1, 3)?)
    }

    /// Returns a volume with the same box and names over another tensor of the same channel count.
    pub fn with_tensor(&self, data: Tensor) -> Result<Self> {
        let volume = Self::new(data, self.aabb())?;
        volume.with_channel_names(self.channel_names.clone())
    }

    /// Runs `f` on the voxel values as one channel-major slice (`C * D * H * W` f32s). On the CPU
    /// this borrows the tensor's memory; on other devices it copies to the host first.
    pub fn with_values<R>(&self, f: impl FnOnce(&[f32]) -> R) -> Result<R> {
        let (storage, layout) = self.data.storage_and_layout();
        if let (Storage::Cpu(cpu), Some((start, end))) = (&*storage, layout.contiguous_offsets()) {
            return Ok(f(&cpu.as_slice::<f32>()?[start..end]));
        }
        drop(storage);
        let host: Vec<f32> = self.data.flatten_all()?.to_vec1()?;
        Ok(f(&host))
    }

    /// Samples every channel at a world point by trilinear interpolation (edge-clamped inside the
    /// box, 0 outside).
    pub fn sample(&self, p: Vec3) -> Result<Vec<f32>> {
        let mut out = vec![0f32; self.channel_count()];
        self.with_values(|values| sample_into(values, &self.grid, p, &mut out))?;
        Ok(out)
    }

    /// Samples every channel at many world points (in parallel), returning a `(P, C)` CPU tensor.
    pub fn sample_batch(&self, points: &[Vec3]) -> Result<Tensor> {
        let channels = self.channel_count();
        let mut out = vec![0f32; points.len() * channels];
        self.with_values(|values| {
            out.par_chunks_mut(channels)
                .zip(points.par_iter())
                .for_each(|(o, &p)| sample_into(values, &self.grid, p, o));
        })?;
        Ok(Tensor::from_vec(
            out,
            (points.len(), channels),
            &Device::Cpu,
        )?)
    }

    /// Returns an error naming the first non-finite value (channel and voxel) and the count.
    pub fn check_finite(&self, what: &str) -> Result<()> {
        self.check_finite_channels(what, 0..self.channel_count())
    }
}

/// Returns `sigma, r, g, b, f0, f1, ...` for `channels` channels.
pub(crate) fn default_channel_names(channels: usize) -> Vec<String> {
    BASE_CHANNELS
        .iter()
        .map(|s| s.to_string())
        .chain((0..channels.saturating_sub(4)).map(|i| format!("f{i}")))
        .take(channels)
        .collect()
}

/// Checks that there is one distinct, non-empty name per channel.
pub(crate) fn validate_channel_names(names: &[String], channels: usize) -> Result<()> {
    if names.len() != channels {
        return Err(invalid(
            "channel_names",
            format!("expected {channels} names, got {}", names.len()),
        ));
    }
    if let Some(bad) = names.iter().find(|n| n.is_empty()) {
        return Err(invalid(
            "channel_names",
            format!("empty channel name {bad:?}"),
        ));
    }
    let mut sorted: Vec<&String> = names.iter().collect();
    sorted.sort();
    if let Some(pair) = sorted.windows(2).find(|p| p[0] == p[1]) {
        return Err(invalid(
            "channel_names",
            format!("duplicate channel name {:?}", pair[0]),
        ));
    }
    Ok(())
}

//! Volumes read block by block: [`VolumeSource`], so that writers and meshers can stream a
//! volume too large to hold at once (a generated scene written on a grid 3 or 5 times finer is
//! 27 or 125 times its own size) through a bounded buffer.
//!
//! A [`RadianceVolume`] is a source (its blocks are copies of its memory); so is an
//! [`Upsampled`](crate::Upsampled) view of one, which computes each block when asked.

use std::ops::Range;

use crate::edit::VoxelRange;
use crate::error::{invalid, Error, Result};
use crate::grid::{GridDims, VoxelGrid};
use crate::volume::RadianceVolume;

/// Blocks are [`VoxelRange`]s (the edits' box of voxels); a reader's usual ones.
impl VoxelRange {
    /// The whole grid.
    #[must_use]
    pub fn all(dims: GridDims) -> Self {
        Self::z_slab(dims, 0..dims.d)
    }

    /// Whole planes `z` of the grid.
    #[must_use]
    pub fn z_slab(dims: GridDims, z: Range<usize>) -> Self {
        Self::new(z, 0..dims.h, 0..dims.w)
    }
}

/// A volume whose values are read one block at a time.
///
/// Implementors give the grid, the channel names and [`VolumeSource::read_block`]; readers never
/// need the whole volume in memory. Blocks of any shape must give the values the whole volume
/// holds there.
///
/// ```
/// use radiance_volume::{Aabb, GridDims, RadianceVolume, VoxelRange, VolumeSource};
/// let v = RadianceVolume::from_fn(GridDims::new(2, 3, 4), Aabb::CUBE, 4, |p, out| {
///     out.copy_from_slice(&[p.x, p.z, p.y, 1.0]);
/// })?;
/// // Density (x) and red (z) of the voxels (z = 1, y = 0..2, x = 3): centres x = 0.75, z = 0.5.
/// let block = v.read_block(0..2, &VoxelRange { z: 1..2, y: 0..2, x: 3..4 })?;
/// assert_eq!(block, vec![0.75, 0.75, 0.5, 0.5]);
/// # Ok::<(), radiance_volume::Error>(())
/// ```
pub trait VolumeSource: Sync + std::fmt::Debug {
    /// The grid: box and cells.
    fn grid(&self) -> VoxelGrid;

    /// One name per channel (`sigma, r, g, b`, then features).
    fn channel_names(&self) -> &[String];

    /// Returns channels `channels` over `region`, channel-major: a `(C', dz, dy, dx)` row-major
    /// array. Errors if a range is empty or beyond the volume.
    fn read_block(&self, channels: Range<usize>, region: &VoxelRange) -> Result<Vec<f32>>;

    /// The cells along each axis.
    fn dims(&self) -> GridDims {
        self.grid().dims
    }

    /// The number of channels.
    fn channel_count(&self) -> usize {
        self.channel_names().len()
    }

    /// How many values a streaming reader of this source asks for at once: [`SLAB_VALUES`]
    /// unless a [`SlabLimit`] says less.
    fn slab_values(&self) -> usize {
        SLAB_VALUES
    }

    /// Fails with [`Error::NonFinite`] naming the first NaN or infinity (in channel, then
    /// voxel order, as [`RadianceVolume::check_finite`]) and their count, reading one slab of
    /// one channel at a time.
    fn check_finite_channels(&self, what: &str, channels: Range<usize>) -> Result<()> {
        let dims = self.dims();
        let (mut count, mut first) = (0usize, None);
        for c in channels {
            for z in z_slabs(dims, 1, self.slab_values()) {
                let values = self.read_block(c..c + 1, &VoxelRange::z_slab(dims, z.clone()))?;
                for (at, v) in values.iter().enumerate().filter(|(_, v)| !v.is_finite()) {
                    count += 1;
                    if first.is_none() {
                        let (zi, y, x) = (
                            z.start + at / (dims.h * dims.w),
                            at / dims.w % dims.h,
                            at % dims.w,
                        );
                        first = Some(format!(
                            "channel {c} ({}), voxel (d={zi}, h={y}, w={x}) = {v}",
                            self.channel_names()[c]
                        ));
                    }
                }
            }
        }
        match first {
            None => Ok(()),
            Some(first) => Err(Error::NonFinite {
                what: what.to_string(),
                count,
                first,
            }),
        }
    }
}

/// Fails unless `channels` is a non-empty range of the `count` channels.
pub(crate) fn check_channels(channels: &Range<usize>, count: usize) -> Result<()> {
    if channels.is_empty() || channels.end > count {
        return Err(invalid(
            "channels",
            format!("{channels:?} is empty or beyond {count} channels"),
        ));
    }
    Ok(())
}

/// How many values a streaming reader asks for at once by default (64 MB of f32): slabs of
/// whole planes as thick as fit, at least one plane.
pub const SLAB_VALUES: usize = 16 << 20;

/// A source read in slabs of at most `values` values instead of [`SLAB_VALUES`]: the same
/// volume in more, smaller reads (less memory held by the reader, more calls).
///
/// ```
/// use radiance_volume::{Aabb, GridDims, RadianceVolume, SlabLimit, VolumeSource};
/// let v = RadianceVolume::from_fn(GridDims::cube(8), Aabb::CUBE, 4, |p, out| out[0] = p.z)?;
/// let thin = SlabLimit::new(&v, 100);
/// assert_eq!(thin.slab_values(), 100);
/// // Written 1 plane at a time instead of all 8 at once: the same file.
/// let dir = tempfile::tempdir()?;
/// let (a, b) = (dir.path().join("thin.safetensors"), dir.path().join("whole.safetensors"));
/// radiance_volume::io::write_safetensors(&thin, &a)?;
/// v.save_safetensors(&b)?;
/// assert_eq!(std::fs::read(a)?, std::fs::read(b)?);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
#[derive(Debug, Clone, Copy)]
pub struct SlabLimit<'a> {
    source: &'a dyn VolumeSource,
    values: usize,
}

impl<'a> SlabLimit<'a> {
    /// `source`, read at most `values` values (at least one plane) at a time.
    pub fn new(source: &'a dyn VolumeSource, values: usize) -> Self {
        Self { source, values }
    }
}

impl VolumeSource for SlabLimit<'_> {
    fn grid(&self) -> VoxelGrid {
        self.source.grid()
    }

    fn channel_names(&self) -> &[String] {
        self.source.channel_names()
    }

    fn read_block(&self, channels: Range<usize>, region: &VoxelRange) -> Result<Vec<f32>> {
        self.source.read_block(channels, region)
    }

    fn slab_values(&self) -> usize {
        self.values.min(self.source.slab_values())
    }
}

/// Splits the planes of `dims` into consecutive slabs of at most `budget` values over
/// `channels` channels (at least one plane each).
///
/// ```
/// use radiance_volume::{z_slabs, GridDims};
/// let slabs: Vec<_> = z_slabs(GridDims::new(5, 10, 10), 4, 1000).collect();
/// assert_eq!(slabs, vec![0..2, 2..4, 4..5]);
/// ```
pub fn z_slabs(
    dims: GridDims,
    channels: usize,
    budget: usize,
) -> impl Iterator<Item = Range<usize>> {
    let per_plane = (dims.h * dims.w * channels).max(1);
    let step = (budget / per_plane).max(1);
    (0..dims.d)
        .step_by(step)
        .map(move |z| z..(z + step).min(dims.d))
}

impl VolumeSource for RadianceVolume {
    fn grid(&self) -> VoxelGrid {
        *RadianceVolume::grid(self)
    }

    fn channel_names(&self) -> &[String] {
        RadianceVolume::channel_names(self)
    }

    fn read_block(&self, channels: Range<usize>, region: &VoxelRange) -> Result<Vec<f32>> {
        let dims = self.dims();
        region.validate(dims)?;
        check_channels(&channels, self.channel_count())?;
        let out_dims = region.dims();
        let mut out = Vec::with_capacity(channels.len() * out_dims.voxel_count());
        self.with_values(|values| {
            for c in channels {
                let plane = &values[c * dims.voxel_count()..][..dims.voxel_count()];
                for z in region.z.clone() {
                    for y in region.y.clone() {
                        let row = dims.index(z, y, 0);
                        out.extend_from_slice(&plane[row + region.x.start..row + region.x.end]);
                    }
                }
            }
        })?;
        Ok(out)
    }
}

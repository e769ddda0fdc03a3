//! Voxel radiance volumes on [candle](https://github.com/huggingface/candle): the volume type,
//! world <-> index transforms, trilinear sampling, resampling, occupancy for empty-space
//! skipping, editing primitives, and I/O (safetensors native; OpenVDB and EXR slices behind the
//! `vdb` and `exr` features).
//!
//! # Conventions (shared by every volgen crate)
//! - World space is right-handed and Z-up, as in Blender; the default box is `[-1, 1]^3`.
//! - A volume tensor is `(C, D, H, W)` (batched `(N, C, D, H, W)`), D along z, H along y,
//!   W along x. Channel 0 is density sigma, channels 1..4 are RGB, further channels optional.
//! - Voxels are cell-centred (as in OpenVDB): `n` cells over `[min, max]` put cell `i`'s centre at
//!   `min + (i + 0.5) * (max - min) / n`. Sampling is trilinear between centres, clamped to the
//!   edge between the outermost centres and the box, and 0 outside the box.
//! - Physical volumes hold sigma >= 0 in 1/world-length and colour in [0, 1]; networks produce raw
//!   volumes, mapped to physical by [`Activation`].
//!
//! ```
//! use radiance_volume::{Aabb, GridDims, RadianceVolume, OccupancyGrid};
//! use glam::Vec3;
//! let v = RadianceVolume::from_fn(GridDims::cube(24), Aabb::CUBE, 4, |p, out| {
//!     out[0] = (0.5 - p.length()).max(0.0) * 10.0;
//!     out[1..4].copy_from_slice(&[0.8, 0.6, 0.3]);
//! })?;
//! let up = v.rescale(4.0 / 3.0)?;
//! assert_eq!(up.dims(), GridDims::cube(32));
//! let occupancy = OccupancyGrid::build(&up, 8, 0.0)?;
//! assert!(occupancy.occupied_fraction() < 1.0);
//! # Ok::<(), radiance_volume::Error>(())
//! ```

mod activation;
mod edit;
mod error;
mod grid;
pub mod io;
mod mask;
mod occupancy;
mod resample;
mod resample_op;
pub mod sample;
mod source;
mod volume;

pub use activation::Activation;
pub use edit::VoxelRange;
pub use error::{Error, Result};
pub use grid::{Aabb, GridDims, VoxelGrid};
pub use mask::dilate_mask;
pub use occupancy::OccupancyGrid;
pub use resample::{resample_tensor, Resampled};
pub use source::{z_slabs, SlabLimit, VolumeSource, SLAB_VALUES};
pub use volume::{RadianceVolume, BASE_CHANNELS};

/// The types most users need, for `use radiance_volume::prelude::*`.
pub mod prelude {
    pub use crate::{
        Aabb, Activation, GridDims, OccupancyGrid, RadianceVolume, VoxelGrid, VoxelRange,
    };
}

/// The README's examples, compiled and run as doc tests.
#[cfg(doctest)]
#[doc = include_str!("../README.md")]
pub struct ReadmeDoctests;

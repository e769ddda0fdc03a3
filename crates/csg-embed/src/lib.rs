//! Positional embeddings for 3D generative models, as candle tensors.
//!
//! The centrepiece is SinGRAV's Cartesian spatial grid (CSG),
//! `e_csg(x, y, z) = 2 [x/W - 1/2, y/H - 1/2, z/U - 1/2]`, a 3-channel volume of spatial anchors
//! that the coarsest generator receives with its noise.
//!
//! Conventions (shared with the rest of volgen, see docs/architecture.md):
//! - A volume is `(C, D, H, W)` (batched `(N, C, D, H, W)`), D along z, H along y, W along x.
//! - Grid channels are ordered x, y, z: channel 0 varies along W, channel 1 along H, channel 2
//!   along D. The 2D grid `(2, H, W)` has channels x, y.
//! - Voxels are cell-centred: the value for index `i` on an axis of `n` cells is
//!   `2 ((i + 0.5)/n - 1/2)`, the voxel centre in `[-1, 1]` ([`csg_coordinate`]). The grid is
//!   therefore symmetric about 0 and matches where the renderer places voxel centres.
//! - Tensors are f32; [`fourier_features`] keeps the dtype of its input.
//!
//! ```
//! use candle_core::Device;
//! let grid = csg_embed::csg_grid_3d(40, 40, 40, &Device::Cpu)?;
//! assert_eq!(grid.dims(), &[3, 40, 40, 40]);
//! let feats = csg_embed::fourier_features(&grid, 0, &csg_embed::octave_frequencies(4))?;
//! assert_eq!(feats.dim(0)?, csg_embed::fourier_channels(3, 4));
//! # Ok::<(), csg_embed::Error>(())
//! ```

mod error;
mod extended;
mod fourier;
mod grid;

pub use error::{Error, Result};
pub use extended::{csg_grid_3d_over, Outside};
pub use fourier::{fourier_channels, fourier_features, octave_frequencies};
pub use grid::{csg_coordinate, csg_grid_2d, csg_grid_3d, csg_grid_3d_batched};

/// The types most users of this crate need, for `use csg_embed::prelude::*;`.
pub mod prelude {
    pub use crate::{csg_grid_2d, csg_grid_3d, fourier_features, octave_frequencies, Outside};
}

/// The README's examples, compiled and run as doc tests.
#[cfg(doctest)]
#[doc = include_str!("../README.md")]
pub struct ReadmeDoctests;

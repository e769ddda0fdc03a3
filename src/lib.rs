//! volgen: reusable 3D-generative building blocks on [candle](https://github.com/huggingface/candle),
//! and SinGRAV, a generative radiance volume learned from multi-view RGB-D images of one scene.
//!
//! This crate only composes the workspace's focused crates (each usable on its own) and ships
//! the `volgen` command-line tool:
//!
//! | module | crate | what it holds |
//! |---|---|---|
//! | [`volume`] | `radiance-volume` | the volume type, sampling, resampling, occupancy, edits, I/O |
//! | [`render`] | `volrender` | cameras, rays, the differentiable volume renderer |
//! | [`embed`] | `csg-embed` | Cartesian spatial grid and Fourier encodings |
//! | [`gan`] | `patch-gan` | Conv3d, generators, patch discriminators, WGAN-GP |
//! | [`swd`] | `swd-loss` | sliced Wasserstein distance and texture losses |
//! | [`dataset`] | `rgbd-dataset` | RGB-D datasets (load, write, resize, bounds) and built-in scenes |
//! | [`metrics`] | `scene-metrics` | Diversity-MV, SIFID-MV, PSNR, SSIM, patch and colour SWD, floaters |
//! | [`fit`] | `volume-fit` | a direct fit of one radiance volume to a dataset |
//! | [`mesh`] | `volume-mesh` | coloured triangle meshes of volumes (glTF, GLB, PLY, OBJ) |
//! | [`singrav`] | `singrav` | the SinGRAV model |
//!
//! ```
//! use volgen::prelude::*;
//! let v = RadianceVolume::from_fn(GridDims::cube(8), Aabb::CUBE, 4, |p, o| o[0] = p.x.max(0.0))?;
//! assert_eq!(v.dims(), GridDims::cube(8));
//! # Ok::<(), volgen::volume::Error>(())
//! ```

pub use csg_embed as embed;
pub use patch_gan as gan;
pub use radiance_volume as volume;
pub use rgbd_dataset as dataset;
pub use scene_metrics as metrics;
pub use singrav;
pub use swd_loss as swd;
pub use volrender as render;
pub use volume_fit as fit;
pub use volume_mesh as mesh;

/// The types most users need: every re-exported crate's own prelude.
pub mod prelude {
    pub use csg_embed::prelude::*;
    pub use patch_gan::prelude::*;
    pub use radiance_volume::prelude::*;
    pub use rgbd_dataset::prelude::*;
    pub use scene_metrics::prelude::*;
    pub use singrav::prelude::*;
    pub use swd_loss::prelude::*;
    pub use volrender::prelude::*;
    pub use volume_fit::prelude::*;
    pub use volume_mesh::prelude::*;
}

//! Coloured triangle meshes of voxel radiance volumes, for the tools that take meshes (game and
//! film tools, web viewers, 3D printers).
//!
//! [`Mesh::from_volume`] extracts the surface where a volume's opacity across one voxel crosses
//! a level ([`MeshOptions::level`], default [`DEFAULT_LEVEL`]) with Surface Nets
//! (`fast-surface-nets`), in the volume's world coordinates, with outward normals and vertex
//! colours from the colour grid; [`Mesh::smoothed`] takes the voxel steps out and
//! [`Mesh::decimated`] keeps a share of the triangles; [`Mesh::write`] writes it as binary glTF (`.glb`), glTF with
//! an embedded buffer (`.gltf`), binary PLY (`.ply`) or OBJ with vertex colours (`.obj`).
//!
//! ```
//! use radiance_volume::{Aabb, GridDims, RadianceVolume};
//! use volume_mesh::{Mesh, MeshOptions};
//! // A grey box filling the middle of the cube.
//! let block = RadianceVolume::from_fn(GridDims::cube(16), Aabb::CUBE, 4, |p, out| {
//!     out[0] = if p.abs().max_element() < 0.5 { 80.0 } else { 0.0 };
//!     out[1..4].fill(0.5);
//! })?;
//! let mesh = Mesh::from_volume(&block, &MeshOptions::default())?;
//! assert!(mesh.is_closed());
//! let dir = tempfile::tempdir()?;
//! mesh.write(&dir.path().join("block.glb"))?;
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

mod error;
mod extract;
mod mesh;
mod refine;
mod write;

pub use error::{Error, Result};
pub use extract::{MeshOptions, DEFAULT_LEVEL};
pub use mesh::Mesh;
pub use write::{srgb_to_linear, MeshFormat};

/// The types most users of this crate need, for `use volume_mesh::prelude::*;`.
pub mod prelude {
    pub use crate::{Mesh, MeshFormat, MeshOptions};
}

/// The README's examples, compiled and run as doc tests.
#[cfg(doctest)]
#[doc = include_str!("../README.md")]
pub struct ReadmeDoctests;

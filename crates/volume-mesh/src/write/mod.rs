//! Mesh files: the format from the file's extension, written atomically (a temporary file
//! beside the target, then renamed).

mod gltf;
mod obj;
mod ply;

pub use gltf::srgb_to_linear;

/// A point or direction of volgen's frame (z up, as its volumes and VDB files are) in the
/// y-up frame glTF prescribes and OBJ readers assume (Blender's glTF and OBJ importers turn it
/// back to z up, so every format lands where the volume's VDB does).
fn y_up(v: [f32; 3]) -> [f32; 3] {
    [v[0], v[2], -v[1]]
}

use std::path::Path;

use crate::error::{Error, Result};
use crate::mesh::Mesh;

/// The mesh formats [`Mesh::write`] writes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MeshFormat {
    /// Binary glTF 2.0 (`.glb`): one file, positions, normals, `COLOR_0` (the colours made
    /// linear, as glTF requires) and indices, y up as glTF prescribes.
    Glb,
    /// glTF 2.0 JSON (`.gltf`) with its buffer embedded as a base64 data URI, y up.
    Gltf,
    /// Binary little-endian PLY (`.ply`) with per-vertex normals and 8-bit colours (sRGB, as
    /// the volume holds them), z up as the volume is.
    Ply,
    /// Wavefront OBJ (`.obj`) with per-vertex colours after the position (`v x y z r g b`, as
    /// Blender, MeshLab and trimesh read them) and normals, y up as OBJ readers assume.
    Obj,
}

impl MeshFormat {
    /// Every format, in the order the docs list them.
    pub const ALL: [MeshFormat; 4] = [Self::Glb, Self::Gltf, Self::Ply, Self::Obj];

    /// The file extension of the format (`glb`, `gltf`, `ply`, `obj`).
    ///
    /// ```
    /// assert_eq!(volume_mesh::MeshFormat::Ply.extension(), "ply");
    /// ```
    pub fn extension(self) -> &'static str {
        match self {
            Self::Glb => "glb",
            Self::Gltf => "gltf",
            Self::Ply => "ply",
            Self::Obj => "obj",
        }
    }

    /// The format an extension names (case-insensitive, without the dot).
    pub fn from_extension(extension: &str) -> Option<Self> {
        Self::ALL
            .into_iter()
            .find(|format| format.extension().eq_ignore_ascii_case(extension))
    }

    /// The format `path`'s extension names.
    pub fn from_path(path: &Path) -> Result<Self> {
        path.extension()
            .and_then(|e| e.to_str())
            .and_then(Self::from_extension)
            .ok_or_else(|| Error::UnknownFormat {
                path: path.to_path_buf(),
            })
    }
}

impl Mesh {
    /// Writes the mesh to `path` in the format its extension names ([`MeshFormat`]),
    /// atomically.
    ///
    /// ```
    /// let triangle = volume_mesh::Mesh {
    ///     positions: vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
    ///     normals: vec![[0.0, 0.0, 1.0]; 3],
    ///     colours: vec![[1.0, 0.0, 0.0]; 3],
    ///     triangles: vec![[0, 1, 2]],
    /// };
    /// let dir = tempfile::tempdir()?;
    /// for name in ["t.glb", "t.gltf", "t.ply", "t.obj"] {
    ///     triangle.write(&dir.path().join(name))?;
    /// }
    /// assert!(triangle.write(&dir.path().join("t.stl")).is_err());
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    pub fn write(&self, path: &Path) -> Result<()> {
        // Checked here too, so that the error names the file.
        if self.triangles.is_empty() {
            return Err(Error::NoSurface {
                why: format!("{}: the mesh has no triangles to write", path.display()),
            });
        }
        let bytes = self.to_bytes(MeshFormat::from_path(path)?)?;
        radiance_volume::io::write_bytes_atomic(path, &bytes)?;
        Ok(())
    }

    /// The bytes [`Mesh::write`] writes in `format` (for a server that sends the file instead
    /// of storing it).
    ///
    /// ```
    /// use volume_mesh::{Mesh, MeshFormat};
    /// let triangle = Mesh {
    ///     positions: vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
    ///     normals: vec![[0.0, 0.0, 1.0]; 3],
    ///     colours: vec![[1.0, 0.0, 0.0]; 3],
    ///     triangles: vec![[0, 1, 2]],
    /// };
    /// let dir = tempfile::tempdir()?;
    /// let path = dir.path().join("t.glb");
    /// triangle.write(&path)?;
    /// assert_eq!(triangle.to_bytes(MeshFormat::Glb)?, std::fs::read(&path)?);
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    pub fn to_bytes(&self, format: MeshFormat) -> Result<Vec<u8>> {
        if self.triangles.is_empty() {
            return Err(Error::NoSurface {
                why: "the mesh has no triangles to write".into(),
            });
        }
        Ok(match format {
            MeshFormat::Glb => gltf::glb(self)?,
            MeshFormat::Gltf => gltf::gltf(self)?,
            MeshFormat::Ply => ply::ply(self),
            MeshFormat::Obj => obj::obj(self),
        })
    }
}

//! Binary little-endian PLY: `x y z nx ny nz` floats and `red green blue` bytes per vertex,
//! a `uchar uint` list of indices per face.

use crate::mesh::Mesh;

pub(super) fn ply(mesh: &Mesh) -> Vec<u8> {
    let header = format!(
        "ply\nformat binary_little_endian 1.0\ncomment written by volgen (volume-mesh)\n\
         element vertex {}\nproperty float x\nproperty float y\nproperty float z\n\
         property float nx\nproperty float ny\nproperty float nz\n\
         property uchar red\nproperty uchar green\nproperty uchar blue\n\
         element face {}\nproperty list uchar uint vertex_indices\nend_header\n",
        mesh.vertex_count(),
        mesh.triangles.len()
    );
    let mut bytes = header.into_bytes();
    bytes.reserve(mesh.vertex_count() * 27 + mesh.triangles.len() * 13);
    for ((p, n), c) in mesh.positions.iter().zip(&mesh.normals).zip(&mesh.colours) {
        for v in p.iter().chain(n) {
            bytes.extend_from_slice(&v.to_le_bytes());
        }
        bytes.extend(c.map(to_byte));
    }
    for t in &mesh.triangles {
        bytes.push(3);
        for i in t {
            bytes.extend_from_slice(&i.to_le_bytes());
        }
    }
    bytes
}

/// A colour channel in [0, 1] as a byte, rounded.
pub(super) fn to_byte(c: f32) -> u8 {
    (c.clamp(0.0, 1.0) * 255.0).round() as u8
}

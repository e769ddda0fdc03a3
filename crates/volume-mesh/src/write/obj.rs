//! Wavefront OBJ with vertex colours (`v x y z r g b`) and normals (`vn`).

use std::fmt::Write;

use super::y_up;
use crate::mesh::Mesh;

pub(super) fn obj(mesh: &Mesh) -> Vec<u8> {
    let mut text =
        String::from("# written by volgen (volume-mesh), y up: v x y z r g b, vn, f v//vn\n");
    for (&p, c) in mesh.positions.iter().zip(&mesh.colours) {
        let p = y_up(p);
        // Infallible: writing to a String.
        let _ = writeln!(
            text,
            "v {} {} {} {:.4} {:.4} {:.4}",
            p[0], p[1], p[2], c[0], c[1], c[2]
        );
    }
    for &n in &mesh.normals {
        let n = y_up(n);
        let _ = writeln!(text, "vn {} {} {}", n[0], n[1], n[2]);
    }
    for t in &mesh.triangles {
        // OBJ indices start at 1.
        let [a, b, c] = t.map(|i| i + 1);
        let _ = writeln!(text, "f {a}//{a} {b}//{b} {c}//{c}");
    }
    text.into_bytes()
}

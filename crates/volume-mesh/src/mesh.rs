//! A coloured triangle mesh and the measures its tests and users check it by.

use std::collections::HashMap;

use glam::{DMat3, DMat4, DVec3};

/// An indexed triangle mesh with a normal and a colour per vertex, in world coordinates.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Mesh {
    /// Vertex positions.
    pub positions: Vec<[f32; 3]>,
    /// Unit outward normals, one per vertex.
    pub normals: Vec<[f32; 3]>,
    /// RGB in [0, 1], one per vertex, as the volume holds colour (the sRGB values of its
    /// dataset's pictures; glTF files get them made linear, [`crate::srgb_to_linear`]).
    pub colours: Vec<[f32; 3]>,
    /// Three vertex indices per triangle, counter-clockwise seen from outside.
    pub triangles: Vec<[u32; 3]>,
}

impl Mesh {
    /// The mesh in another frame: positions mapped by the affine `map` (e.g. the similarity
    /// that takes a dataset's frame back to its capture's), normals by its inverse transpose
    /// (renormalised), and the triangles' winding reversed when `map` mirrors, so that they stay
    /// counter-clockwise seen from outside. `None` when `map` is singular or not finite.
    ///
    /// ```
    /// use glam::{DMat4, DVec3};
    /// let triangle = volume_mesh::Mesh {
    ///     positions: vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
    ///     normals: vec![[0.0, 0.0, 1.0]; 3],
    ///     colours: vec![[1.0; 3]; 3],
    ///     triangles: vec![[0, 1, 2]],
    /// };
    /// let map = DMat4::from_scale_rotation_translation(
    ///     DVec3::splat(2.0),
    ///     glam::DQuat::from_rotation_x(std::f64::consts::FRAC_PI_2),
    ///     DVec3::new(0.0, 0.0, 5.0),
    /// );
    /// let moved = triangle.transformed(map).unwrap();
    /// assert!((moved.area() - 4.0 * triangle.area()).abs() < 1e-9);
    /// // The +z normal turned a quarter about x points along -y.
    /// assert!((DVec3::from(moved.normals[0].map(f64::from)) - DVec3::NEG_Y).length() < 1e-6);
    /// assert!((moved.positions[2][2] - 7.0).abs() < 1e-6);
    /// ```
    pub fn transformed(&self, map: DMat4) -> Option<Mesh> {
        let linear = DMat3::from_mat4(map);
        let det = linear.determinant();
        if !map.is_finite() || det.abs() < 1e-12 {
            return None;
        }
        let normal_map = linear.inverse().transpose();
        let f32s = |v: DVec3| v.to_array().map(|c| c as f32);
        let as_f64 = |p: &[f32; 3]| DVec3::from(p.map(f64::from));
        Some(Mesh {
            positions: self
                .positions
                .iter()
                .map(|p| f32s(map.transform_point3(as_f64(p))))
                .collect(),
            normals: self
                .normals
                .iter()
                .map(|n| f32s((normal_map * as_f64(n)).normalize_or_zero()))
                .collect(),
            colours: self.colours.clone(),
            triangles: if det > 0.0 {
                self.triangles.clone()
            } else {
                self.triangles.iter().map(|&[a, b, c]| [a, c, b]).collect()
            },
        })
    }

    /// The number of vertices.
    pub fn vertex_count(&self) -> usize {
        self.positions.len()
    }

    /// The sum of the triangles' areas.
    ///
    /// ```
    /// let square = volume_mesh::Mesh {
    ///     positions: vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]],
    ///     normals: vec![[0.0, 0.0, 1.0]; 4],
    ///     colours: vec![[1.0; 3]; 4],
    ///     triangles: vec![[0, 1, 2], [0, 2, 3]],
    /// };
    /// assert!((square.area() - 1.0).abs() < 1e-12);
    /// ```
    pub fn area(&self) -> f64 {
        self.triangles
            .iter()
            .map(|t| {
                let [a, b, c] = self.corners(t);
                (b - a).cross(c - a).length() / 2.0
            })
            .sum()
    }

    /// The volume the mesh encloses (the divergence theorem over its triangles): positive for a
    /// closed mesh whose triangles face outwards, meaningless for an open one
    /// ([`Mesh::is_closed`]).
    pub fn enclosed_volume(&self) -> f64 {
        self.triangles
            .iter()
            .map(|t| {
                let [a, b, c] = self.corners(t);
                a.dot(b.cross(c)) / 6.0
            })
            .sum()
    }

    /// Whether the mesh is closed (watertight) and consistently oriented: every edge is used as
    /// often in one direction as in the other, so no triangle's edge is left open. Surface Nets
    /// joins two pieces of matter that touch only along an edge by four triangles there (see
    /// [`Mesh::non_manifold_edges`]), which still closes the surface.
    pub fn is_closed(&self) -> bool {
        let directed = self.directed_edges();
        directed
            .iter()
            .all(|(&(a, b), &count)| directed.get(&(b, a)) == Some(&count))
    }

    /// The number of edges used by more than two triangles: where two pieces of matter touch
    /// along an edge only, and a tool that needs a manifold (some 3D-printing slicers) would
    /// split them. 0 for a single smooth object.
    pub fn non_manifold_edges(&self) -> usize {
        let mut undirected: HashMap<(u32, u32), u32> = HashMap::new();
        for ((a, b), count) in self.directed_edges() {
            *undirected.entry((a.min(b), a.max(b))).or_default() += count;
        }
        undirected.values().filter(|&&count| count > 2).count()
    }

    /// How often each directed edge `(from, to)` appears in the triangles.
    fn directed_edges(&self) -> HashMap<(u32, u32), u32> {
        let mut directed: HashMap<(u32, u32), u32> = HashMap::new();
        for t in &self.triangles {
            for (a, b) in [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])] {
                *directed.entry((a, b)).or_default() += 1;
            }
        }
        directed
    }

    fn corners(&self, t: &[u32; 3]) -> [DVec3; 3] {
        t.map(|i| {
            let p = self.positions[i as usize];
            DVec3::new(f64::from(p[0]), f64::from(p[1]), f64::from(p[2]))
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A tetrahedron wound counter-clockwise seen from outside.
    fn tetrahedron() -> Mesh {
        Mesh {
            positions: vec![[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            normals: vec![
                [-1.0, -1.0, -1.0],
                [1.0, 0.0, 0.0],
                [0.0, 1.0, 0.0],
                [0.0, 0.0, 1.0],
            ],
            colours: vec![[0.5; 3]; 4],
            triangles: vec![[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]],
        }
    }

    #[test]
    fn a_transformed_mesh_keeps_its_inside_inside() {
        let mesh = tetrahedron();
        assert!((mesh.enclosed_volume() - 1.0 / 6.0).abs() < 1e-9);
        // Doubled and turned: eight times the volume, still positive (outward winding).
        let similar = DMat4::from_scale_rotation_translation(
            DVec3::splat(2.0),
            glam::DQuat::from_rotation_y(1.0),
            DVec3::new(3.0, -1.0, 2.0),
        );
        let moved = mesh.transformed(similar).unwrap();
        assert!((moved.enclosed_volume() - 8.0 / 6.0).abs() < 1e-5);
        // Mirrored: the winding is reversed with it, and the normals still point out.
        let mirrored = mesh
            .transformed(DMat4::from_scale(DVec3::new(-1.0, 1.0, 1.0)))
            .unwrap();
        assert!((mirrored.enclosed_volume() - 1.0 / 6.0).abs() < 1e-9);
        assert_eq!(mirrored.normals[1], [-1.0, 0.0, 0.0]);
        assert!(mirrored.is_closed());
        // Singular or non-finite maps are refused.
        assert!(mesh
            .transformed(DMat4::from_scale(DVec3::new(1.0, 0.0, 1.0)))
            .is_none());
        assert!(mesh
            .transformed(DMat4::from_scale(DVec3::splat(f64::NAN)))
            .is_none());
    }
}

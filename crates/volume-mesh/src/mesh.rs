//! A coloured triangle mesh and the measures its tests and users check it by.

use std::collections::HashMap;

use glam::DVec3;

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

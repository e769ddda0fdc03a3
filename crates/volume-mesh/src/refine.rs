//! What a mesh can go through after extraction: Taubin smoothing of the voxel steps Surface
//! Nets leaves ([`Mesh::smoothed`]) and fewer triangles for game engines and web viewers
//! ([`Mesh::decimated`], meshoptimizer's edge collapses through the `meshopt` crate).

use glam::Vec3;
use meshopt::SimplifyOptions;

use crate::error::{invalid, Result};
use crate::mesh::Mesh;

/// Taubin's shrinking step: each vertex moves half-way to the mean of its neighbours.
const TAUBIN_LAMBDA: f32 = 0.5;
/// Taubin's inflating step, `1 / (k_PB - 1 / lambda)` with the pass-band frequency
/// `k_PB = 0.1` his paper suggests: undoes the shrinking at low frequencies, so the mesh keeps
/// its size while the voxel steps (high frequencies) fade.
const TAUBIN_MU: f32 = -0.5263;

/// How much a vertex colour weighs in the decimation's error against its position (positions
/// are measured relative to the mesh's extent): colour edges between kinds of matter stay
/// where they are.
const COLOUR_WEIGHT: f32 = 0.5;

impl Mesh {
    /// The mesh after `iterations` rounds of Taubin's lambda|mu smoothing (each vertex moved
    /// towards, then away from, the mean of its neighbours), with normals recomputed from the
    /// smoothed triangles. Removes the voxel steps of Surface Nets with little shrinking;
    /// triangles, colours and topology are kept.
    ///
    /// ```
    /// use radiance_volume::{Aabb, GridDims, RadianceVolume};
    /// use volume_mesh::{Mesh, MeshOptions};
    /// let ball = RadianceVolume::from_fn(GridDims::cube(20), Aabb::CUBE, 4, |p, out| {
    ///     out[0] = if p.length() < 0.6 { 100.0 } else { 0.0 };
    /// })?;
    /// let mesh = Mesh::from_volume(&ball, &MeshOptions::default())?;
    /// let smooth = mesh.smoothed(5);
    /// assert_eq!(smooth.triangles, mesh.triangles);
    /// assert!((smooth.enclosed_volume() / mesh.enclosed_volume() - 1.0).abs() < 0.03);
    /// # Ok::<(), volume_mesh::Error>(())
    /// ```
    #[must_use]
    pub fn smoothed(&self, iterations: usize) -> Mesh {
        let neighbours = self.neighbours();
        let mut positions: Vec<Vec3> = self.positions.iter().map(|&p| Vec3::from(p)).collect();
        for _ in 0..iterations {
            for factor in [TAUBIN_LAMBDA, TAUBIN_MU] {
                positions = positions
                    .iter()
                    .zip(&neighbours)
                    .map(|(&p, around)| {
                        if around.is_empty() {
                            return p;
                        }
                        let mean = around.iter().map(|&j| positions[j as usize]).sum::<Vec3>()
                            / around.len() as f32;
                        p + factor * (mean - p)
                    })
                    .collect();
            }
        }
        let mut mesh = Mesh {
            positions: positions.iter().map(|p| p.to_array()).collect(),
            ..self.clone()
        };
        mesh.normals = mesh.face_normals_at_vertices();
        mesh
    }

    /// The mesh with about `fraction` of its triangles (in (0, 1]), by meshoptimizer's edge
    /// collapses weighing position and colour error, unused vertices dropped. Vertices keep
    /// their positions, colours and normals; a closed mesh stays closed. Errors unless
    /// `fraction` lies in (0, 1].
    ///
    /// ```
    /// use radiance_volume::{Aabb, GridDims, RadianceVolume};
    /// use volume_mesh::{Mesh, MeshOptions};
    /// let ball = RadianceVolume::from_fn(GridDims::cube(20), Aabb::CUBE, 4, |p, out| {
    ///     out[0] = if p.length() < 0.6 { 100.0 } else { 0.0 };
    /// })?;
    /// let mesh = Mesh::from_volume(&ball, &MeshOptions::default())?;
    /// let light = mesh.decimated(0.25)?;
    /// assert!(light.triangles.len() <= mesh.triangles.len() / 4 + 2);
    /// assert!(light.is_closed());
    /// assert!(mesh.decimated(0.0).is_err());
    /// # Ok::<(), volume_mesh::Error>(())
    /// ```
    pub fn decimated(&self, fraction: f32) -> Result<Mesh> {
        if !(fraction > 0.0 && fraction <= 1.0) {
            return Err(invalid(
                "fraction",
                format!("expected a share of the triangles in (0, 1], got {fraction}"),
            ));
        }
        if fraction == 1.0 || self.triangles.is_empty() {
            return Ok(self.clone());
        }
        let indices: Vec<u32> = self.triangles.as_flattened().to_vec();
        let target = ((indices.len() as f64 * f64::from(fraction)) as usize / 3) * 3;
        let colours = self.colours.as_flattened();
        let unlocked = vec![false; self.vertex_count()];
        let kept = meshopt::simplify_with_attributes_and_locks_decoder(
            &indices,
            &self.positions,
            colours,
            &[COLOUR_WEIGHT; 3],
            std::mem::size_of::<[f32; 3]>(),
            &unlocked,
            target,
            // No bound on the error: the triangle count decides.
            f32::MAX,
            SimplifyOptions::None,
            None,
        );
        Ok(self.with_triangles(&kept))
    }

    /// The mesh of the triangles `indices` (three per triangle, into this mesh's vertices),
    /// holding only the vertices they use, in their first use's order.
    fn with_triangles(&self, indices: &[u32]) -> Mesh {
        let mut new_index = vec![u32::MAX; self.vertex_count()];
        let mut mesh = Mesh::default();
        let mut triangles = Vec::with_capacity(indices.len() / 3);
        for t in indices.chunks_exact(3) {
            let mut corner = |old: u32| {
                let slot = &mut new_index[old as usize];
                if *slot == u32::MAX {
                    *slot = mesh.positions.len() as u32;
                    mesh.positions.push(self.positions[old as usize]);
                    mesh.normals.push(self.normals[old as usize]);
                    mesh.colours.push(self.colours[old as usize]);
                }
                *slot
            };
            let (a, b, c) = (corner(t[0]), corner(t[1]), corner(t[2]));
            triangles.push([a, b, c]);
        }
        mesh.triangles = triangles;
        mesh
    }

    /// Each vertex's neighbours along the triangles' edges, without repeats.
    fn neighbours(&self) -> Vec<Vec<u32>> {
        let mut around: Vec<Vec<u32>> = vec![Vec::new(); self.vertex_count()];
        for t in &self.triangles {
            for (a, b) in [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])] {
                for (from, to) in [(a, b), (b, a)] {
                    let list = &mut around[from as usize];
                    if !list.contains(&to) {
                        list.push(to);
                    }
                }
            }
        }
        around
    }

    /// Unit vertex normals as the area-weighted sum of the normals of the triangles around
    /// each vertex (counter-clockwise triangles seen from outside point them outwards).
    fn face_normals_at_vertices(&self) -> Vec<[f32; 3]> {
        let mut sums = vec![Vec3::ZERO; self.vertex_count()];
        for t in &self.triangles {
            let [a, b, c] = t.map(|i| Vec3::from(self.positions[i as usize]));
            // Twice the area along the normal: larger triangles weigh more.
            let n = (b - a).cross(c - a);
            for &i in t {
                sums[i as usize] += n;
            }
        }
        sums.iter()
            .map(|n| n.normalize_or_zero().to_array())
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use radiance_volume::{Aabb, GridDims, RadianceVolume};

    use super::*;
    use crate::MeshOptions;

    /// A ball of radius `r` in the cube on a `n`^3 grid, coloured red above z = 0 and blue
    /// below.
    fn ball(n: usize, r: f32) -> Mesh {
        let volume = RadianceVolume::from_fn(GridDims::cube(n), Aabb::CUBE, 4, |p, out| {
            out[0] = if p.length() < r { 100.0 } else { 0.0 };
            out[1] = if p.z > 0.0 { 1.0 } else { 0.0 };
            out[3] = if p.z > 0.0 { 0.0 } else { 1.0 };
        })
        .unwrap();
        Mesh::from_volume(&volume, &MeshOptions::default()).unwrap()
    }

    /// The spread of the vertices' distances from the centre, relative to their mean: how far
    /// a mesh of a sphere is from round.
    fn roughness(mesh: &Mesh) -> (f64, f64) {
        let radii: Vec<f64> = mesh
            .positions
            .iter()
            .map(|p| f64::from(Vec3::from(*p).length()))
            .collect();
        let mean = radii.iter().sum::<f64>() / radii.len() as f64;
        let var = radii.iter().map(|r| (r - mean).powi(2)).sum::<f64>() / radii.len() as f64;
        (mean, var.sqrt() / mean)
    }

    #[test]
    fn smoothing_rounds_a_voxel_ball_without_shrinking_it() {
        let mesh = ball(24, 0.6);
        let (radius, rough) = roughness(&mesh);
        let smooth = mesh.smoothed(10);
        let (smooth_radius, smooth_rough) = roughness(&smooth);
        assert!(smooth_rough < 0.8 * rough, "{rough} -> {smooth_rough}");
        assert!(
            (smooth_radius / radius - 1.0).abs() < 0.01,
            "{radius} -> {smooth_radius}"
        );
        assert!(smooth.is_closed());
        assert_eq!(smooth.colours, mesh.colours);
        // Normals point outwards, along the position on a ball centred at 0.
        for (p, n) in smooth.positions.iter().zip(&smooth.normals) {
            let (p, n) = (Vec3::from(*p).normalize(), Vec3::from(*n));
            assert!((n.length() - 1.0).abs() < 1e-4 && p.dot(n) > 0.9, "{p} {n}");
        }
        assert_eq!(mesh.smoothed(0).positions, mesh.positions);
    }

    #[test]
    fn decimation_keeps_the_shape_closed_and_the_colours_apart() {
        let mesh = ball(24, 0.6);
        let sphere = 4.0 / 3.0 * std::f64::consts::PI * 0.6f64.powi(3);
        for fraction in [0.5, 0.2, 0.05] {
            let light = mesh.decimated(fraction).unwrap();
            let share = light.triangles.len() as f64 / mesh.triangles.len() as f64;
            assert!(share <= f64::from(fraction) + 0.01, "{fraction}: {share}");
            assert!(share >= 0.5 * f64::from(fraction), "{fraction}: {share}");
            assert!(light.is_closed(), "{fraction}");
            assert!(
                (light.enclosed_volume() / sphere - 1.0).abs() < 0.1,
                "{fraction}"
            );
            // Every vertex is used, and the red cap's vertices are still above the blue's.
            let mut used = vec![false; light.vertex_count()];
            light
                .triangles
                .iter()
                .flatten()
                .for_each(|&i| used[i as usize] = true);
            assert!(used.iter().all(|&u| u));
            for (p, c) in light.positions.iter().zip(&light.colours) {
                if c[0] > 0.99 {
                    assert!(p[2] > -0.1, "red vertex at {p:?}");
                }
                if c[2] > 0.99 {
                    assert!(p[2] < 0.1, "blue vertex at {p:?}");
                }
            }
        }
        assert_eq!(mesh.decimated(1.0).unwrap(), mesh);
        for bad in [0.0, -0.5, 1.5, f32::NAN] {
            let err = mesh.decimated(bad).unwrap_err().to_string();
            assert!(err.contains("fraction"), "{err}");
        }
    }
}

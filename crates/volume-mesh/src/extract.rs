//! The surface of a volume's matter: an isosurface of per-voxel opacity by Surface Nets
//! (`fast-surface-nets`), coloured from the volume's colour grid.

use fast_surface_nets::ndshape::{RuntimeShape, Shape};
use fast_surface_nets::{surface_nets, SurfaceNetsBuffer};
use glam::Vec3;
use radiance_volume::RadianceVolume;

use crate::error::{invalid, Error, Result};
use crate::mesh::Mesh;

/// The opacity level [`MeshOptions::default`] takes: the surface where a voxel stops a quarter
/// of the light crossing it. Chosen by measurement (docs/formats.md, "Meshes"): rendered from a
/// dataset's cameras, meshes at 0.25 match the volume's own rendering 2.9-4.6 dB better in colour
/// than at 0.5, whose surface leaves out the soft edges a camera sees, and keep the colours of
/// denser matter better than at 0.1, whose surface lies in faint fog.
pub const DEFAULT_LEVEL: f32 = 0.25;

/// How [`Mesh::from_volume`] makes a mesh.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MeshOptions {
    /// The surface's level of opacity across one voxel, `1 - exp(-sigma * voxel)`, in (0, 1):
    /// lower takes in thinner matter (fog, soft edges), higher only the dense core.
    pub level: f32,
}

impl Default for MeshOptions {
    fn default() -> Self {
        Self {
            level: DEFAULT_LEVEL,
        }
    }
}

impl Mesh {
    /// The surface of `volume`'s matter (density, then RGB; `(4+, D, H, W)` over its box) where
    /// its opacity across a voxel crosses `options.level`, in the volume's world coordinates.
    /// The grid is padded with empty voxels so that matter touching the box's faces gives a
    /// closed surface; vertex colours are the volume's colour interpolated where the matter is
    /// (weighted by density, so empty neighbours' colours do not bleed in), normals point out of
    /// the matter.
    ///
    /// ```
    /// use radiance_volume::{Aabb, GridDims, RadianceVolume};
    /// use volume_mesh::{Mesh, MeshOptions};
    /// // A red ball of radius 0.5 in the cube [-1, 1]^3.
    /// let ball = RadianceVolume::from_fn(GridDims::cube(24), Aabb::CUBE, 4, |p, out| {
    ///     out[0] = if p.length() < 0.5 { 100.0 } else { 0.0 };
    ///     out[1] = 1.0; // red everywhere
    /// })?;
    /// let mesh = Mesh::from_volume(&ball, &MeshOptions::default())?;
    /// assert!(mesh.is_closed());
    /// let sphere = 4.0 / 3.0 * std::f64::consts::PI * 0.125;
    /// assert!((mesh.enclosed_volume() / sphere - 1.0).abs() < 0.1);
    /// assert!(mesh.colours.iter().all(|c| (c[0] - 1.0).abs() < 1e-5));
    /// # Ok::<(), volume_mesh::Error>(())
    /// ```
    pub fn from_volume(volume: &RadianceVolume, options: &MeshOptions) -> Result<Self> {
        let level = options.level;
        if !(level > 0.0 && level < 1.0) {
            return Err(invalid(
                "level",
                format!("expected an opacity in (0, 1), got {level}"),
            ));
        }
        if volume.channel_count() < 4 {
            return Err(invalid(
                "volume",
                format!(
                    "needs density and RGB channels (4), has {}",
                    volume.channel_count()
                ),
            ));
        }
        volume.check_finite("volume")?;
        let dims = volume.dims();
        let (w, h, d) = (dims.w, dims.h, dims.d);
        let voxel = volume.grid().voxel_size();
        let values: Vec<f32> = volume.tensor().narrow(0, 0, 4)?.flatten_all()?.to_vec1()?;
        let opacity_of = |sigma: f32, axis_voxel: f32| 1.0 - (-sigma * axis_voxel).exp();
        // Opacity across the voxel's shortest edge (all edges are equal on cubic grids).
        let edge = voxel.min_element();
        // Padded with empty voxels, one below and two above on every axis (Surface Nets makes no
        // faces on the last plane of its array); x fastest, as the volume stores it.
        let shape = RuntimeShape::<u32, 3>::new([w as u32 + 3, h as u32 + 3, d as u32 + 3]);
        let mut sdf = vec![level; shape.size() as usize];
        let mut peak = 0f32;
        for z in 0..d {
            for y in 0..h {
                for x in 0..w {
                    let opacity = opacity_of(values[(z * h + y) * w + x].max(0.0), edge);
                    peak = peak.max(opacity);
                    let at = shape.linearize([x as u32 + 1, y as u32 + 1, z as u32 + 1]);
                    // Negative inside the matter: the normals then point out of it.
                    sdf[at as usize] = level - opacity;
                }
            }
        }
        if peak <= level {
            return Err(Error::NoSurface {
                why: format!(
                    "the volume's densest voxel has opacity {peak:.3}, not above the level \
                     {level} (an empty volume, or thin matter: try a lower --level)"
                ),
            });
        }
        let mut buffer = SurfaceNetsBuffer::default();
        let last = [w as u32 + 2, h as u32 + 2, d as u32 + 2];
        surface_nets(&sdf, &shape, [0; 3], last, &mut buffer);
        let min = volume.aabb().min;
        // Padded index p is voxel p - 1, whose centre is min + (p - 1 + 0.5) * voxel.
        let to_world = |p: [f32; 3]| min + (Vec3::from(p) - Vec3::splat(0.5)) * voxel;
        let positions: Vec<Vec3> = buffer.positions.iter().map(|&p| to_world(p)).collect();
        let colours = positions
            .iter()
            .map(|&p| matter_colour(&values, (w, h, d), volume.aabb(), p))
            .collect();
        let normals = buffer
            .normals
            .iter()
            .map(|n| {
                // The SDF's gradient in index space, scaled to world space (non-cubic voxels).
                let world = Vec3::from(*n) / voxel;
                world.normalize_or_zero().to_array()
            })
            .collect();
        let triangles = buffer
            .indices
            .chunks_exact(3)
            .map(|t| [t[0], t[1], t[2]])
            .collect();
        Ok(Self {
            positions: positions.iter().map(|p| p.to_array()).collect(),
            normals,
            colours,
            triangles,
        })
    }
}

/// The colour of the matter at world point `p`: the trilinear, density-weighted mean of the
/// eight nearest voxels' colours (cell-centred, clamped at the box), so a surface vertex between
/// a solid voxel and an empty one takes the solid one's colour.
fn matter_colour(
    values: &[f32],
    (w, h, d): (usize, usize, usize),
    aabb: radiance_volume::Aabb,
    p: Vec3,
) -> [f32; 3] {
    let cells = w * h * d;
    let size = [w, h, d];
    let cell = (p - aabb.min) / (aabb.max - aabb.min) * Vec3::new(w as f32, h as f32, d as f32)
        - Vec3::splat(0.5);
    // Per axis: the two neighbours and the second one's weight.
    let taps: Vec<(usize, usize, f32)> = (0..3)
        .map(|axis| {
            let n = size[axis];
            let c = cell[axis].clamp(0.0, (n - 1) as f32);
            let low = c.floor() as usize;
            let high = (low + 1).min(n - 1);
            (low, high, c - low as f32)
        })
        .collect();
    let (mut weighted, mut total) = ([0f32; 3], 0f32);
    for corner in 0..8 {
        let pick = |axis: usize| {
            let (low, high, t) = taps[axis];
            if corner >> axis & 1 == 1 {
                (high, t)
            } else {
                (low, 1.0 - t)
            }
        };
        let ((x, wx), (y, wy), (z, wz)) = (pick(0), pick(1), pick(2));
        let i = (z * h + y) * w + x;
        let sigma = values[i].max(0.0);
        let weight = wx * wy * wz * sigma;
        for c in 0..3 {
            weighted[c] += weight * values[(c + 1) * cells + i];
        }
        total += weight;
    }
    if total > 0.0 {
        weighted.map(|c| (c / total).clamp(0.0, 1.0))
    } else {
        // No matter among the eight (a vertex at the padding): the nearest voxel's colour.
        let i = (taps[2].0 * h + taps[1].0) * w + taps[0].0;
        [1, 2, 3].map(|c| values[c * cells + i].clamp(0.0, 1.0))
    }
}

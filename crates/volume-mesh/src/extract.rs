//! The surface of a volume's matter: an isosurface of per-voxel opacity by Surface Nets
//! (`fast-surface-nets`), coloured from the volume's colour grid.

use std::ops::Range;

use fast_surface_nets::ndshape::{RuntimeShape, Shape};
use fast_surface_nets::{surface_nets, SurfaceNetsBuffer};
use glam::Vec3;
use radiance_volume::{z_slabs, GridDims, RadianceVolume, VolumeSource, VoxelGrid, VoxelRange};

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
        Self::from_source(volume, options)
    }

    /// [`Mesh::from_volume`] of any [`VolumeSource`] (for example a volume computed block by
    /// block on a finer grid, [`radiance_volume::Resampled`]), read a slab of planes at a time:
    /// beside the mesh, only the opacity grid (one f32 per voxel) and Surface Nets' index of it
    /// are held whole.
    ///
    /// ```
    /// use radiance_volume::{Aabb, GridDims, RadianceVolume, Resampled};
    /// use volume_mesh::{Mesh, MeshOptions};
    /// let ball = RadianceVolume::from_fn(GridDims::cube(12), Aabb::CUBE, 4, |p, out| {
    ///     out[0] = if p.length() < 0.5 { 100.0 } else { 0.0 };
    ///     out[2] = 1.0; // green
    /// })?;
    /// // The ball on a grid 3 times finer, never held whole.
    /// let fine = Mesh::from_source(&Resampled::finer(ball.clone(), 3)?, &MeshOptions::default())?;
    /// let coarse = Mesh::from_volume(&ball, &MeshOptions::default())?;
    /// assert!(fine.is_closed() && fine.triangles.len() > 4 * coarse.triangles.len());
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    pub fn from_source(volume: &dyn VolumeSource, options: &MeshOptions) -> Result<Self> {
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
        volume.check_finite_channels("volume", 0..volume.channel_count())?;
        let dims = volume.dims();
        let (w, h, d) = (dims.w, dims.h, dims.d);
        let voxel = volume.grid().voxel_size();
        let opacity_of = |sigma: f32, axis_voxel: f32| 1.0 - (-sigma * axis_voxel).exp();
        // Opacity across the voxel's shortest edge (all edges are equal on cubic grids).
        let edge = voxel.min_element();
        // Padded with empty voxels, one below and two above on every axis (Surface Nets makes no
        // faces on the last plane of its array); x fastest, as the volume stores it.
        let shape = RuntimeShape::<u32, 3>::new([w as u32 + 3, h as u32 + 3, d as u32 + 3]);
        let mut sdf = vec![level; shape.size() as usize];
        let mut peak = 0f32;
        for slab in z_slabs(dims, 1, volume.slab_values()) {
            let sigma = volume.read_block(0..1, &VoxelRange::z_slab(dims, slab.clone()))?;
            for (z, plane) in slab.zip(sigma.chunks_exact(w * h)) {
                for (y, row) in plane.chunks_exact(w).enumerate() {
                    for (x, &s) in row.iter().enumerate() {
                        let opacity = opacity_of(s.max(0.0), edge);
                        peak = peak.max(opacity);
                        let at = shape.linearize([x as u32 + 1, y as u32 + 1, z as u32 + 1]);
                        // Negative inside the matter: the normals then point out of it.
                        sdf[at as usize] = level - opacity;
                    }
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
        drop(sdf);
        let grid = volume.grid();
        // Padded index p is voxel p - 1, whose centre is min + (p - 1 + 0.5) * voxel.
        let to_world = |p: [f32; 3]| grid.aabb.min + (Vec3::from(p) - Vec3::splat(0.5)) * voxel;
        let positions: Vec<Vec3> = buffer.positions.iter().map(|&p| to_world(p)).collect();
        let colours = matter_colours(volume, &positions)?;
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

/// The matter's colour at every point ([`matter_colour`]), reading the volume one slab of
/// planes at a time: each point needs the two planes around it.
fn matter_colours(volume: &dyn VolumeSource, points: &[Vec3]) -> Result<Vec<[f32; 3]>> {
    let grid = volume.grid();
    let dims = grid.dims;
    let taps: Vec<[Tap; 3]> = points.iter().map(|&p| taps(&grid, p)).collect();
    let mut order: Vec<usize> = (0..points.len()).collect();
    order.sort_unstable_by_key(|&i| taps[i][2].low);
    let mut colours = vec![[0f32; 3]; points.len()];
    let mut next = 0;
    for slab in z_slabs(dims, 4, volume.slab_values()) {
        let planes = slab.start..(slab.end + 1).min(dims.d);
        let block = volume.read_block(0..4, &VoxelRange::z_slab(dims, planes.clone()))?;
        while next < order.len() && taps[order[next]][2].low < slab.end {
            let i = order[next];
            colours[i] = matter_colour(&block, planes.clone(), dims, &taps[i]);
            next += 1;
        }
    }
    Ok(colours)
}

/// One axis of a trilinear lookup: the two neighbouring cells and the second one's weight.
#[derive(Debug, Clone, Copy)]
struct Tap {
    low: usize,
    high: usize,
    t: f32,
}

/// The trilinear taps of world point `p` along x, y and z (cell-centred, clamped at the box).
fn taps(grid: &VoxelGrid, p: Vec3) -> [Tap; 3] {
    let size = grid.dims.xyz();
    let cell = (p - grid.aabb.min) / (grid.aabb.max - grid.aabb.min)
        * Vec3::new(size[0] as f32, size[1] as f32, size[2] as f32)
        - Vec3::splat(0.5);
    [0, 1, 2].map(|axis| {
        let n = size[axis];
        let c = cell[axis].clamp(0.0, (n - 1) as f32);
        let low = c.floor() as usize;
        Tap {
            low,
            high: (low + 1).min(n - 1),
            t: c - low as f32,
        }
    })
}

/// The colour of the matter at a point with trilinear `taps`: the density-weighted mean of the
/// eight nearest voxels' colours, so a surface vertex between a solid voxel and an empty one
/// takes the solid one's colour. `block` holds channels 0..4 over the planes `planes` (which
/// include the point's two).
fn matter_colour(block: &[f32], planes: Range<usize>, dims: GridDims, taps: &[Tap; 3]) -> [f32; 3] {
    let (w, h) = (dims.w, dims.h);
    let cells = planes.len() * w * h;
    let index = |x: usize, y: usize, z: usize| ((z - planes.start) * h + y) * w + x;
    let (mut weighted, mut total) = ([0f32; 3], 0f32);
    for corner in 0..8 {
        let pick = |axis: usize| {
            let Tap { low, high, t } = taps[axis];
            if corner >> axis & 1 == 1 {
                (high, t)
            } else {
                (low, 1.0 - t)
            }
        };
        let ((x, wx), (y, wy), (z, wz)) = (pick(0), pick(1), pick(2));
        let i = index(x, y, z);
        let sigma = block[i].max(0.0);
        let weight = wx * wy * wz * sigma;
        for c in 0..3 {
            weighted[c] += weight * block[(c + 1) * cells + i];
        }
        total += weight;
    }
    if total > 0.0 {
        weighted.map(|c| (c / total).clamp(0.0, 1.0))
    } else {
        // No matter among the eight (a vertex at the padding): the nearest voxel's colour.
        let i = index(taps[0].low, taps[1].low, taps[2].low);
        [1, 2, 3].map(|c| block[c * cells + i].clamp(0.0, 1.0))
    }
}

//! A coarse occupancy grid for exact empty-space skipping.
//!
//! Cell `c` of the occupancy grid (with `k` voxels per cell and axis) covers the world region of
//! voxels `c*k .. (c+1)*k`. A trilinear sample anywhere in that region reads voxels `c*k - 1 ..=
//! (c+1)*k` (its footprint reaches one voxel across each border), so the cell is marked occupied
//! when any voxel of that dilated block has density above the threshold. With the default
//! threshold 0 and physical densities (>= 0), a cell marked empty has density exactly 0 at every
//! point inside it, and samples there may be skipped without changing a result. With a threshold
//! `tau > 0`, density inside an empty cell is at most `tau` (a trilinear blend never exceeds its
//! corners), an approximation whose bound is stated.
//!
//! Memory is one bool per cell; building is one pass over the density voxels that marks at most
//! 27 cells per voxel above the threshold, in parallel over slabs of cells.

use glam::Vec3;
use rayon::prelude::*;

use crate::error::{invalid, Result};
use crate::grid::{Aabb, GridDims, VoxelGrid};
use crate::volume::RadianceVolume;

/// A coarse grid of booleans: which blocks of voxels can hold non-zero density.
///
/// ```
/// use radiance_volume::{Aabb, GridDims, OccupancyGrid, RadianceVolume};
/// use glam::Vec3;
/// let v = RadianceVolume::from_fn(GridDims::cube(32), Aabb::CUBE, 4, |p, out| {
///     out[0] = if p.x > 0.5 && p.y > 0.5 && p.z > 0.5 { 1.0 } else { 0.0 };
/// })?;
/// let occ = OccupancyGrid::build(&v, 8, 0.0)?;
/// assert_eq!(occ.dims(), GridDims::cube(4));
/// assert!(occ.is_occupied_at(Vec3::splat(0.9)));
/// assert!(!occ.is_occupied_at(Vec3::splat(-0.9)));
/// # Ok::<(), radiance_volume::Error>(())
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct OccupancyGrid {
    origin: Vec3,
    cell_size: Vec3,
    voxels_per_cell: usize,
    dims: GridDims,
    occupied: Vec<bool>,
}

impl OccupancyGrid {
    /// Builds the grid from a physical volume's density with `voxels_per_cell` voxels per cell
    /// and axis (e.g. 4 or 8), marking cells whose footprint holds density `> threshold`.
    /// NaN densities count as occupied.
    pub fn build(volume: &RadianceVolume, voxels_per_cell: usize, threshold: f32) -> Result<Self> {
        let voxels = volume.dims().voxel_count();
        volume.with_values(|values| {
            Self::from_density(&values[..voxels], volume.grid(), voxels_per_cell, threshold)
        })?
    }

    /// Builds the grid from density values alone, `(z, y, x)` row-major over `grid` (what
    /// [`OccupancyGrid::build`] reads of a volume), for densities that are not a volume's channel
    /// 0, such as activated raw densities.
    ///
    /// ```
    /// use radiance_volume::{Aabb, GridDims, OccupancyGrid, VoxelGrid};
    /// use glam::Vec3;
    /// let grid = VoxelGrid::new(Aabb::CUBE, GridDims::cube(8))?;
    /// let mut density = vec![0.0f32; 512];
    /// density[grid.dims.index(7, 7, 7)] = 2.0;
    /// let occ = OccupancyGrid::from_density(&density, &grid, 4, 0.0)?;
    /// assert!(occ.is_occupied_at(Vec3::splat(0.9)) && !occ.is_occupied_at(Vec3::splat(-0.9)));
    /// assert!(OccupancyGrid::from_density(&density[1..], &grid, 4, 0.0).is_err());
    /// # Ok::<(), radiance_volume::Error>(())
    /// ```
    pub fn from_density(
        density: &[f32],
        grid: &VoxelGrid,
        voxels_per_cell: usize,
        threshold: f32,
    ) -> Result<Self> {
        if voxels_per_cell == 0 {
            return Err(invalid(
                "voxels_per_cell",
                "expected at least 1 voxel per cell",
            ));
        }
        if !(threshold >= 0.0 && threshold.is_finite()) {
            return Err(invalid(
                "threshold",
                format!("expected a finite threshold >= 0, got {threshold}"),
            ));
        }
        let vd = grid.dims;
        if density.len() != vd.voxel_count() {
            return Err(invalid(
                "density",
                format!(
                    "expected {} values for a {} x {} x {} grid, got {}",
                    vd.voxel_count(),
                    vd.d,
                    vd.h,
                    vd.w,
                    density.len()
                ),
            ));
        }
        let k = voxels_per_cell;
        let dims = GridDims::new(vd.d.div_ceil(k), vd.h.div_ceil(k), vd.w.div_ceil(k));
        let mut occupied = vec![false; dims.voxel_count()];
        // In parallel over slabs of cells with the same z: each reads the voxel slices whose
        // footprint reaches it (its own and one more on each side) and marks only its cells.
        let slab = dims.h * dims.w;
        occupied
            .par_chunks_mut(slab)
            .enumerate()
            .for_each(|(slab_z, cells)| {
                let first = (slab_z * k).saturating_sub(1);
                let last = ((slab_z + 1) * k).min(vd.d - 1);
                for z in first..=last {
                    if !cells_of_voxel(z, k, dims.d).contains(&Some(slab_z)) {
                        continue;
                    }
                    for y in 0..vd.h {
                        let cy = cells_of_voxel(y, k, dims.h);
                        let row = &density[vd.index(z, y, 0)..vd.index(z, y, 0) + vd.w];
                        for (x, &s) in row.iter().enumerate() {
                            // NaN counts as occupied: unknown density is never skipped.
                            if s > threshold || s.is_nan() {
                                let cx = cells_of_voxel(x, k, dims.w);
                                for &b in cy.iter().flatten() {
                                    for &c in cx.iter().flatten() {
                                        cells[b * dims.w + c] = true;
                                    }
                                }
                            }
                        }
                    }
                }
            });
        Ok(Self {
            origin: grid.aabb.min,
            cell_size: grid.voxel_size() * k as f32,
            voxels_per_cell: k,
            dims,
            occupied,
        })
    }

    /// Returns the number of cells per axis.
    #[must_use]
    pub fn dims(&self) -> GridDims {
        self.dims
    }

    /// Returns the number of voxels per cell and axis.
    #[must_use]
    pub fn voxels_per_cell(&self) -> usize {
        self.voxels_per_cell
    }

    /// Returns the world size of one cell (the last cell along an axis may reach beyond the
    /// volume's box when its size is not a multiple of `voxels_per_cell`).
    #[must_use]
    pub fn cell_size(&self) -> Vec3 {
        self.cell_size
    }

    /// Returns the world box of the cells (starting at the volume's minimum corner).
    #[must_use]
    pub fn aabb(&self) -> Aabb {
        let [w, h, d] = self.dims.xyz();
        Aabb {
            min: self.origin,
            max: self.origin + self.cell_size * Vec3::new(w as f32, h as f32, d as f32),
        }
    }

    /// Tells whether cell `(z, y, x)` is occupied.
    ///
    /// # Panics
    /// Panics if the cell is outside the grid.
    #[must_use]
    pub fn is_occupied(&self, z: usize, y: usize, x: usize) -> bool {
        self.occupied[self.dims.index(z, y, x)]
    }

    /// Returns the cell `(z, y, x)` holding a world point, clamped into the grid.
    #[must_use]
    pub fn cell_of(&self, p: Vec3) -> [usize; 3] {
        let c = ((p - self.origin) / self.cell_size).floor();
        let clamp = |v: f32, n: usize| (v.max(0.0) as usize).min(n - 1);
        [
            clamp(c.z, self.dims.d),
            clamp(c.y, self.dims.h),
            clamp(c.x, self.dims.w),
        ]
    }

    /// Tells whether the cell holding world point `p` is occupied (false outside the cells' box).
    #[must_use]
    pub fn is_occupied_at(&self, p: Vec3) -> bool {
        if !self.aabb().contains(p) {
            return false;
        }
        let [z, y, x] = self.cell_of(p);
        self.is_occupied(z, y, x)
    }

    /// Returns the fraction of occupied cells.
    #[must_use]
    pub fn occupied_fraction(&self) -> f32 {
        self.occupied.iter().filter(|&&o| o).count() as f32 / self.occupied.len() as f32
    }
}

/// Returns the cells (up to 3) along one axis whose dilated footprint `c*k - 1 ..= (c+1)*k`
/// contains voxel `v`.
fn cells_of_voxel(v: usize, k: usize, cells: usize) -> [Option<usize>; 3] {
    let own = v / k;
    // v is the last voxel before cell own+1: that cell's footprint starts one voxel early.
    let next = ((v + 1).is_multiple_of(k) && own + 1 < cells).then_some(own + 1);
    // v is the first voxel of its cell: the previous cell's footprint ends one voxel late.
    let prev = (v.is_multiple_of(k) && own > 0).then(|| own - 1);
    [Some(own), next, prev]
}

//! Boxes, grid sizes and the world <-> index transform of a cell-centred voxel grid.
//!
//! Index coordinates are continuous and put the centre of cell `i` at `i`: a grid of `n` cells over
//! `[min, max]` has cell `i` centred at `min + (i + 0.5) * (max - min) / n` (OpenVDB's convention).
//! Vectors in index space are ordered like world vectors, `(x, y, z)` = `(w, h, d)`.

use glam::Vec3;

use crate::error::{invalid, Result};

/// An axis-aligned box in world space.
///
/// ```
/// use radiance_volume::Aabb;
/// use glam::Vec3;
/// let b = Aabb::default();
/// assert_eq!(b.size(), Vec3::splat(2.0));
/// assert!(b.contains(Vec3::ZERO));
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Aabb {
    /// The corner with the smallest coordinates.
    pub min: Vec3,
    /// The corner with the largest coordinates.
    pub max: Vec3,
}

impl Default for Aabb {
    /// Returns the default volume of interest, `[-1, 1]^3`.
    fn default() -> Self {
        Self::CUBE
    }
}

impl Aabb {
    /// The box `[-1, 1]^3`, the default volume of interest.
    pub const CUBE: Self = Self {
        min: Vec3::NEG_ONE,
        max: Vec3::ONE,
    };

    /// Creates a box, checking that it is finite and has positive extent on every axis.
    pub fn try_new(min: Vec3, max: Vec3) -> Result<Self> {
        if !(min.is_finite() && max.is_finite()) || min.cmpge(max).any() {
            return Err(invalid(
                "aabb",
                format!("expected finite min < max on every axis, got min {min} max {max}"),
            ));
        }
        Ok(Self { min, max })
    }

    /// Returns the extent `max - min`.
    #[must_use]
    pub fn size(&self) -> Vec3 {
        self.max - self.min
    }

    /// Returns the centre point.
    #[must_use]
    pub fn center(&self) -> Vec3 {
        (self.min + self.max) * 0.5
    }

    /// Tells whether `p` lies in the closed box.
    #[must_use]
    pub fn contains(&self, p: Vec3) -> bool {
        p.cmpge(self.min).all() && p.cmple(self.max).all()
    }

    /// Returns the interval `(t_near, t_far)` of ray parameters `t` for which `origin + t * dir`
    /// lies in the box (slab method), or `None` when the line misses it or only touches it at
    /// `t < 0` entirely. `t_near` is negative when the origin is inside. Zero components of `dir`
    /// are handled exactly: such an axis constrains nothing if the origin lies within its slab and
    /// excludes the ray otherwise.
    ///
    /// ```
    /// use radiance_volume::Aabb;
    /// use glam::Vec3;
    /// let (t0, t1) = Aabb::CUBE.intersect_ray(Vec3::new(0.0, 0.0, 3.0), Vec3::NEG_Z).unwrap();
    /// assert_eq!((t0, t1), (2.0, 4.0));
    /// ```
    #[must_use]
    pub fn intersect_ray(&self, origin: Vec3, dir: Vec3) -> Option<(f32, f32)> {
        let mut t_near = f32::NEG_INFINITY;
        let mut t_far = f32::INFINITY;
        for axis in 0..3 {
            let (o, d, lo, hi) = (origin[axis], dir[axis], self.min[axis], self.max[axis]);
            if d == 0.0 {
                if o < lo || o > hi {
                    return None;
                }
                continue;
            }
            let (a, b) = ((lo - o) / d, (hi - o) / d);
            t_near = t_near.max(a.min(b));
            t_far = t_far.min(a.max(b));
        }
        (t_near <= t_far && t_far >= 0.0 && t_near.is_finite() && t_far.is_finite())
            .then_some((t_near, t_far))
    }
}

/// The number of cells of a grid along z (`d`), y (`h`) and x (`w`).
///
/// ```
/// use radiance_volume::GridDims;
/// let dims = GridDims::cube(40);
/// assert_eq!(dims.voxel_count(), 64_000);
/// assert_eq!(dims.index(1, 2, 3), 1 * 1600 + 2 * 40 + 3);
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct GridDims {
    /// Cells along z.
    pub d: usize,
    /// Cells along y.
    pub h: usize,
    /// Cells along x.
    pub w: usize,
}

impl GridDims {
    /// Creates grid dimensions.
    #[must_use]
    pub const fn new(d: usize, h: usize, w: usize) -> Self {
        Self { d, h, w }
    }

    /// Creates an `n x n x n` grid.
    #[must_use]
    pub const fn cube(n: usize) -> Self {
        Self { d: n, h: n, w: n }
    }

    /// Returns `d * h * w`.
    #[must_use]
    pub const fn voxel_count(&self) -> usize {
        self.d * self.h * self.w
    }

    /// Returns the row-major offset of cell `(z, y, x)` in a `(D, H, W)` array.
    #[must_use]
    pub const fn index(&self, z: usize, y: usize, x: usize) -> usize {
        (z * self.h + y) * self.w + x
    }

    /// Returns the sizes as `(x, y, z)` = `(w, h, d)`, the order of world vectors.
    #[must_use]
    pub fn xyz(&self) -> [usize; 3] {
        [self.w, self.h, self.d]
    }

    /// Returns an error unless every size is at least 1.
    pub fn validate(&self) -> Result<()> {
        if self.voxel_count() == 0 {
            return Err(invalid(
                "dims",
                format!("every grid size must be >= 1, got {self:?}"),
            ));
        }
        Ok(())
    }
}

/// A cell-centred grid laid over a world box: the world <-> index transform.
///
/// ```
/// use radiance_volume::{Aabb, GridDims, VoxelGrid};
/// use glam::Vec3;
/// let g = VoxelGrid::new(Aabb::CUBE, GridDims::cube(4)).unwrap();
/// // Cell 0 spans [-1, -0.5]; its centre is at -0.75.
/// assert_eq!(g.index_to_world(Vec3::ZERO), Vec3::splat(-0.75));
/// assert_eq!(g.world_to_index(Vec3::splat(-0.75)), Vec3::ZERO);
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VoxelGrid {
    /// The world box the grid covers.
    pub aabb: Aabb,
    /// The number of cells per axis.
    pub dims: GridDims,
}

impl VoxelGrid {
    /// Creates a grid, checking the box and the sizes.
    pub fn new(aabb: Aabb, dims: GridDims) -> Result<Self> {
        Aabb::try_new(aabb.min, aabb.max)?;
        dims.validate()?;
        Ok(Self { aabb, dims })
    }

    /// Returns the size of one cell along each world axis.
    #[must_use]
    pub fn voxel_size(&self) -> Vec3 {
        self.aabb.size() / self.dims_xyz()
    }

    /// Returns the cell counts as a float vector `(w, h, d)`.
    #[must_use]
    pub fn dims_xyz(&self) -> Vec3 {
        let [w, h, d] = self.dims.xyz();
        Vec3::new(w as f32, h as f32, d as f32)
    }

    /// Maps a world point to continuous index coordinates (cell `i`'s centre at `i`).
    #[must_use]
    pub fn world_to_index(&self, p: Vec3) -> Vec3 {
        (p - self.aabb.min) / self.voxel_size() - 0.5
    }

    /// Maps continuous index coordinates to a world point.
    #[must_use]
    pub fn index_to_world(&self, i: Vec3) -> Vec3 {
        self.aabb.min + (i + 0.5) * self.voxel_size()
    }

    /// Returns the world position of the centre of cell `(z, y, x)`.
    #[must_use]
    pub fn cell_center(&self, z: usize, y: usize, x: usize) -> Vec3 {
        self.index_to_world(Vec3::new(x as f32, y as f32, z as f32))
    }
}

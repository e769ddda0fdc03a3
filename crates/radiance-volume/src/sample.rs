//! Trilinear interpolation of a cell-centred grid at world points (CPU, on plain slices).
//!
//! The rule of docs/architecture.md: exact values at cell centres, linear blends between neighbouring
//! centres, values clamped to the edge between the outermost centres and the box faces, and every
//! channel 0 outside the box (density 0 there is the rule that matters; colour and features are
//! 0 too so that outside points are clearly "nothing").

use glam::Vec3;

use crate::grid::VoxelGrid;

/// The two neighbouring cells and the blend weight of the second, along one axis.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AxisLerp {
    /// The lower neighbour (clamped into the grid).
    pub i0: usize,
    /// The upper neighbour (clamped into the grid; equal to `i0` at the edges).
    pub i1: usize,
    /// The weight of `i1`; `i0` gets `1 - t`.
    pub t: f32,
}

impl AxisLerp {
    /// Computes the neighbours of continuous index coordinate `u` (cell `i`'s centre at `u = i`)
    /// on an axis of `n >= 1` cells, clamping to the outermost centres.
    #[inline]
    #[must_use]
    pub fn new(u: f32, n: usize) -> Self {
        let last = (n - 1) as f32;
        let u = u.clamp(0.0, last);
        let i0 = (u.floor() as usize).min(n - 1);
        let i1 = (i0 + 1).min(n - 1);
        Self {
            i0,
            i1,
            t: u - i0 as f32,
        }
    }
}

/// Samples every channel of a `(C, D, H, W)` row-major array at world point `p` into `out`
/// (length C), by the rule in the module docs.
///
/// # Panics
/// Panics if `values.len() != out.len() * grid.dims.voxel_count()`.
pub fn sample_into(values: &[f32], grid: &VoxelGrid, p: Vec3, out: &mut [f32]) {
    let voxels = grid.dims.voxel_count();
    assert_eq!(
        values.len(),
        out.len() * voxels,
        "values do not match the grid and channel count"
    );
    if !grid.aabb.contains(p) {
        out.fill(0.0);
        return;
    }
    let u = grid.world_to_index(p);
    let dims = grid.dims;
    let (lx, ly, lz) = (
        AxisLerp::new(u.x, dims.w),
        AxisLerp::new(u.y, dims.h),
        AxisLerp::new(u.z, dims.d),
    );
    let corners = [
        (
            lz.i0,
            ly.i0,
            lx.i0,
            (1.0 - lz.t) * (1.0 - ly.t) * (1.0 - lx.t),
        ),
        (lz.i0, ly.i0, lx.i1, (1.0 - lz.t) * (1.0 - ly.t) * lx.t),
        (lz.i0, ly.i1, lx.i0, (1.0 - lz.t) * ly.t * (1.0 - lx.t)),
        (lz.i0, ly.i1, lx.i1, (1.0 - lz.t) * ly.t * lx.t),
        (lz.i1, ly.i0, lx.i0, lz.t * (1.0 - ly.t) * (1.0 - lx.t)),
        (lz.i1, ly.i0, lx.i1, lz.t * (1.0 - ly.t) * lx.t),
        (lz.i1, ly.i1, lx.i0, lz.t * ly.t * (1.0 - lx.t)),
        (lz.i1, ly.i1, lx.i1, lz.t * ly.t * lx.t),
    ];
    for (c, o) in out.iter_mut().enumerate() {
        let channel = &values[c * voxels..(c + 1) * voxels];
        *o = corners
            .iter()
            .map(|&(z, y, x, w)| w * channel[dims.index(z, y, x)])
            .sum();
    }
}

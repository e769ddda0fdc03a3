//! The structures empty-space skipping reads: per occupancy cell, how far away the nearest
//! occupied cell is (so a ray can leap over many empty cells at once), and per voxel, whether
//! the trilinear corner block it starts is all empty.

use radiance_volume::{GridDims, OccupancyGrid, VoxelGrid};
use rayon::prelude::*;

use crate::config::RenderConfig;
use crate::error::Result;
use crate::kernel::Real;

/// An occupancy grid as the kernel reads it: per cell, flattened (z, y, x), the chessboard
/// distance in cells to the nearest occupied cell (0: occupied; capped at `u8::MAX`).
#[derive(Debug, Clone)]
pub(crate) struct CellDistances {
    pub(crate) distance: Vec<u8>,
    /// Cells along x, y, z.
    pub(crate) n: [usize; 3],
    /// Voxels per cell edge.
    pub(crate) k: usize,
}

impl CellDistances {
    /// Builds radiance-volume's occupancy grid (threshold 0) of physical densities, `(z, y, x)`
    /// row-major over a `dims` grid in the config's box, and the distances over it.
    pub(crate) fn from_density(
        density: &[f32],
        dims: GridDims,
        cfg: &RenderConfig,
    ) -> Result<Self> {
        let grid = VoxelGrid::new(cfg.aabb, dims)?;
        Ok(Self::from_grid(&OccupancyGrid::from_density(
            density,
            &grid,
            cfg.occupancy_cell,
            0.0,
        )?))
    }

    /// The distances over an occupancy grid.
    fn from_grid(grid: &OccupancyGrid) -> Self {
        let dims = grid.dims();
        let mut occupied = Vec::with_capacity(dims.voxel_count());
        for z in 0..dims.d {
            for y in 0..dims.h {
                occupied.extend((0..dims.w).map(|x| grid.is_occupied(z, y, x)));
            }
        }
        let n = [dims.w, dims.h, dims.d];
        Self {
            distance: chessboard_distances(&occupied, n),
            n,
            k: grid.voxels_per_cell(),
        }
    }
}

/// Returns, per cell of an `n = [x, y, z]` grid flattened (z, y, x), the chessboard (L-inf)
/// distance to the nearest `occupied` cell, capped at `u8::MAX` (and `u8::MAX` everywhere when
/// none is occupied).
///
/// Two raster passes of the 26-neighbour chamfer mask with unit weights, which is exact for
/// this metric: every cell takes the minimum over the neighbours already visited plus one,
/// first in forward order, then in backward order.
fn chessboard_distances(occupied: &[bool], n: [usize; 3]) -> Vec<u8> {
    // The grid with a border one cell wide that stays at the cap, so that every cell of the
    // grid has all 26 neighbours and the passes need no bounds tests.
    let p = n.map(|c| c + 2);
    let padded_index = |x: usize, y: usize, z: usize| ((z + 1) * p[1] + y + 1) * p[0] + x + 1;
    let mut dist = vec![u8::MAX; p[0] * p[1] * p[2]];
    for z in 0..n[2] {
        for y in 0..n[1] {
            let row = (z * n[1] + y) * n[0];
            for x in 0..n[0] {
                if occupied[row + x] {
                    dist[padded_index(x, y, z)] = 0;
                }
            }
        }
    }
    // Flat offsets of the neighbours before a cell in raster order (z slowest): the first 13 of
    // the 26; the ones after it are their negations.
    let (sx, sy) = (1isize, p[0] as isize);
    let sz = sy * p[1] as isize;
    let before: Vec<isize> = (-1..=1)
        .flat_map(|dz| {
            (-1..=1).flat_map(move |dy| (-1..=1).map(move |dx| dz * sz + dy * sy + dx * sx))
        })
        .take(13)
        .collect();
    let mut relax = |i: usize, sign: isize| {
        let mut best = dist[i];
        for &o in &before {
            best = best.min(dist[i.wrapping_add_signed(sign * o)].saturating_add(1));
        }
        dist[i] = best;
    };
    for z in 0..n[2] {
        for y in 0..n[1] {
            for x in 0..n[0] {
                relax(padded_index(x, y, z), 1);
            }
        }
    }
    for z in (0..n[2]).rev() {
        for y in (0..n[1]).rev() {
            for x in (0..n[0]).rev() {
                relax(padded_index(x, y, z), -1);
            }
        }
    }
    let mut out = Vec::with_capacity(occupied.len());
    for z in 0..n[2] {
        for y in 0..n[1] {
            let start = padded_index(0, y, z);
            out.extend_from_slice(&dist[start..start + n[0]]);
        }
    }
    out
}

/// Flags each voxel whose trilinear corner block (itself and its +1 neighbours along each axis,
/// clamped at the far faces exactly as the sampler clamps) holds density exactly 0 everywhere: a
/// sample whose lower corner is such a voxel has density exactly 0. `sigma` is the density
/// plane, `(D, H, W)` row-major.
///
/// Only rows that cross an occupied cell are examined; every other voxel is flagged without
/// looking: it lies in an empty cell, whose footprint (the cell and one voxel beyond) holds no
/// density, and its corner block lies in that footprint.
pub(crate) fn empty_blocks<T: Real>(
    sigma: &[T],
    dims: GridDims,
    cells: &CellDistances,
) -> Vec<bool> {
    let (w, h, d) = (dims.w, dims.h, dims.d);
    let k = cells.k;
    let mut blocks = vec![true; dims.voxel_count()];
    // Row by row (no per-voxel index arithmetic): a voxel's block is empty when its column of
    // the four rows (this one and the +1 rows along y and z) is all zero, and so is the next
    // column along x.
    blocks.par_chunks_mut(w).enumerate().for_each(|(row, out)| {
        let (z, y) = (row / h, row % h);
        let cell_row = ((z / k) * cells.n[1] + y / k) * cells.n[0];
        if !cells.distance[cell_row..cell_row + cells.n[0]].contains(&0) {
            return;
        }
        let (z1, y1) = ((z + 1).min(d - 1), (y + 1).min(h - 1));
        let rows = [(z, y), (z, y1), (z1, y), (z1, y1)].map(|(a, b)| {
            let start = dims.index(a, b, 0);
            &sigma[start..start + w]
        });
        let column_empty = |x: usize| rows.iter().all(|r| r[x] == T::zero());
        let mut next_empty = column_empty(w - 1);
        for x in (0..w).rev() {
            let here_empty = column_empty(x);
            out[x] = here_empty && next_empty;
            next_empty = here_empty;
        }
    });
    blocks
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// The two passes give the brute-force minimum of the chessboard distance, on random grids
    /// of several shapes and fill rates (including none occupied).
    #[test]
    fn chessboard_distances_match_brute_force() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        for (n, rate) in [
            ([5, 4, 6], 0.1),
            ([9, 1, 7], 0.02),
            ([1, 1, 1], 0.5),
            ([12, 10, 11], 0.005),
            ([3, 3, 3], 0.0),
        ] {
            let cells = n[0] * n[1] * n[2];
            let occupied: Vec<bool> = (0..cells).map(|_| rng.random::<f64>() < rate).collect();
            let coords = |i: usize| [i % n[0], (i / n[0]) % n[1], i / (n[0] * n[1])];
            let got = chessboard_distances(&occupied, n);
            for (i, &distance) in got.iter().enumerate() {
                let p = coords(i);
                let expected = (0..cells)
                    .filter(|&j| occupied[j])
                    .map(|j| {
                        let q = coords(j);
                        (0..3).map(|a| p[a].abs_diff(q[a])).max().unwrap_or(0)
                    })
                    .min()
                    .map_or(u8::MAX, |d| d.min(255) as u8);
                assert_eq!(distance, expected, "{n:?} cell {p:?}");
            }
        }
    }

    /// The flags equal the definition (all 8 clamped corners have density 0), including those
    /// set without looking in empty cells.
    #[test]
    fn empty_blocks_match_the_definition() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        for dims in [
            GridDims::new(4, 5, 6),
            GridDims::new(1, 1, 7),
            GridDims::new(3, 1, 1),
        ] {
            let density: Vec<f32> = (0..dims.voxel_count())
                .map(|_| if rng.random::<f64>() < 0.15 { 1.0 } else { 0.0 })
                .collect();
            let cfg = RenderConfig {
                occupancy_cell: 2,
                ..RenderConfig::default()
            };
            let cells = CellDistances::from_density(&density, dims, &cfg).unwrap();
            let got = empty_blocks(&density, dims, &cells);
            for z in 0..dims.d {
                for y in 0..dims.h {
                    for x in 0..dims.w {
                        let mut empty = true;
                        for (a, b, c) in [
                            (z, y, x),
                            (z, y, x + 1),
                            (z, y + 1, x),
                            (z, y + 1, x + 1),
                            (z + 1, y, x),
                            (z + 1, y, x + 1),
                            (z + 1, y + 1, x),
                            (z + 1, y + 1, x + 1),
                        ] {
                            let voxel =
                                dims.index(a.min(dims.d - 1), b.min(dims.h - 1), c.min(dims.w - 1));
                            empty &= density[voxel] == 0.0;
                        }
                        assert_eq!(got[dims.index(z, y, x)], empty, "{dims:?} ({z}, {y}, {x})");
                    }
                }
            }
        }
    }
}

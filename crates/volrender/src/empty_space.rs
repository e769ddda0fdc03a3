//! The structures empty-space skipping reads: per occupancy cell, how far away the nearest
//! occupied cell is (so a ray can leap over many empty cells at once), and per voxel, whether
//! the trilinear corner block it starts is all empty.

use candle_core::Tensor;
use radiance_volume::{GridDims, OccupancyGrid, RadianceVolume};
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
    /// Builds radiance-volume's occupancy grid (threshold 0) of one `(C, D, H, W)` volume and
    /// the distances over it.
    ///
    /// For f64 volumes the grid is built from the f32-rounded density, so densities below
    /// f32's smallest subnormal (about 1.4e-45) count as empty.
    pub(crate) fn build(volume: &Tensor, cfg: &RenderConfig) -> Result<Self> {
        let physical = RadianceVolume::new(volume.narrow(0, 0, 4)?.detach(), cfg.aabb)?;
        let grid = OccupancyGrid::build(&physical, cfg.occupancy_cell, 0.0)?;
        let dims = grid.dims();
        let mut occupied = Vec::with_capacity(dims.voxel_count());
        for z in 0..dims.d {
            for y in 0..dims.h {
                occupied.extend((0..dims.w).map(|x| grid.is_occupied(z, y, x)));
            }
        }
        let n = [dims.w, dims.h, dims.d];
        Ok(Self {
            distance: chessboard_distances(&occupied, n),
            n,
            k: grid.voxels_per_cell(),
        })
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
    let mut dist: Vec<u8> = occupied
        .iter()
        .map(|&o| if o { 0 } else { u8::MAX })
        .collect();
    let offsets: Vec<[isize; 3]> = (-1..=1)
        .flat_map(|dz| (-1..=1).flat_map(move |dy| (-1..=1).map(move |dx| [dx, dy, dz])))
        .collect();
    // Neighbours before a cell in raster order (z slowest): the first 13 offsets; after it:
    // the last 13.
    let (before, after) = (&offsets[..13], &offsets[14..]);
    let flat = |p: [usize; 3]| (p[2] * n[1] + p[1]) * n[0] + p[0];
    let mut relax = |p: [usize; 3], neighbours: &[[isize; 3]]| {
        let mut best = dist[flat(p)];
        for o in neighbours {
            let q = [0, 1, 2].map(|a| p[a].checked_add_signed(o[a]).filter(|&c| c < n[a]));
            if let [Some(x), Some(y), Some(z)] = q {
                best = best.min(dist[flat([x, y, z])].saturating_add(1));
            }
        }
        dist[flat(p)] = best;
    };
    let cells = || {
        (0..n[2]).flat_map(move |z| (0..n[1]).flat_map(move |y| (0..n[0]).map(move |x| [x, y, z])))
    };
    for p in cells() {
        relax(p, before);
    }
    let all: Vec<[usize; 3]> = cells().collect();
    for &p in all.iter().rev() {
        relax(p, after);
    }
    dist
}

/// Flags each voxel whose trilinear corner block (itself and its +1 neighbours along each axis,
/// clamped at the far faces exactly as the sampler clamps) holds density exactly 0 everywhere: a
/// sample whose lower corner is such a voxel has density exactly 0.
pub(crate) fn empty_blocks<T: Real>(data: &[[T; 4]], dims: GridDims) -> Vec<bool> {
    (0..dims.voxel_count())
        .into_par_iter()
        .map(|i| {
            let (z, y, x) = (i / (dims.h * dims.w), (i / dims.w) % dims.h, i % dims.w);
            let (z1, y1, x1) = (
                (z + 1).min(dims.d - 1),
                (y + 1).min(dims.h - 1),
                (x + 1).min(dims.w - 1),
            );
            [z, z1].iter().all(|&a| {
                [y, y1].iter().all(|&b| {
                    [x, x1]
                        .iter()
                        .all(|&c| data[dims.index(a, b, c)][0] == T::zero())
                })
            })
        })
        .collect()
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
}

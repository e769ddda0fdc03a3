//! Trilinear corners of a sample in continuous index space as 8 voxel indices and weights: the
//! form the kernels' nested lerps (see `chunk`) are tested against, and the one the portable
//! path computes with tensor ops (`portable::geometry`).
//!
//! This is radiance-volume's sampling rule (`radiance_volume::sample::sample_into`) in generic
//! precision: index coordinate `u` puts cell `i`'s centre at `u = i`; inside the box
//! (`-0.5 <= u <= n - 0.5`) values are edge-clamped; outside, every channel is 0.

use super::Real;

/// The 8 voxels a sample blends and their weights, ordered (z, y, x) with x fastest.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Corners<T> {
    pub(crate) idx: [usize; 8],
    pub(crate) w: [T; 8],
}

/// Returns the lower and upper neighbour and the upper's weight along an axis of `n` cells, for
/// a coordinate `u` already known to be in `[-0.5, n - 0.5]` (so not NaN).
#[inline(always)]
fn axis<T: Real>(u: T, n: usize) -> (usize, usize, T) {
    let last = n - 1;
    let top = T::of(last as f64);
    // Plain comparisons, not `max`/`min`: u is not NaN, and they compile to single min/max
    // instructions instead of NaN-aware sequences.
    let uc = if u > T::zero() { u } else { T::zero() };
    let uc = if uc < top { uc } else { top };
    // 0 <= uc <= last, so truncation is floor.
    let i0 = uc.truncate_index() as usize;
    let i1 = usize::min(i0 + 1, last);
    (i0, i1, uc - T::of(i0 as f64))
}

/// Returns the corners of index-space point `u = [x, y, z]`, or `None` outside the box (and for
/// NaN coordinates).
#[inline(always)]
pub(crate) fn corners<T: Real>(n: [usize; 3], u: [T; 3]) -> Option<Corners<T>> {
    let half = T::of(0.5);
    for a in 0..3 {
        // `!(..)` also rejects NaN.
        if !(u[a] >= -half && u[a] <= T::of(n[a] as f64) - half) {
            return None;
        }
    }
    let (x0, x1, fx) = axis(u[0], n[0]);
    let (y0, y1, fy) = axis(u[1], n[1]);
    let (z0, z1, fz) = axis(u[2], n[2]);
    let one = T::one();
    let (gx, gy, gz) = (one - fx, one - fy, one - fz);
    let (row00, row01) = ((z0 * n[1] + y0) * n[0], (z0 * n[1] + y1) * n[0]);
    let (row10, row11) = ((z1 * n[1] + y0) * n[0], (z1 * n[1] + y1) * n[0]);
    let (w00, w01, w10, w11) = (gz * gy, gz * fy, fz * gy, fz * fy);
    Some(Corners {
        idx: [
            row00 + x0,
            row00 + x1,
            row01 + x0,
            row01 + x1,
            row10 + x0,
            row10 + x1,
            row11 + x0,
            row11 + x1,
        ],
        w: [
            w00 * gx,
            w00 * fx,
            w01 * gx,
            w01 * fx,
            w10 * gx,
            w10 * fx,
            w11 * gx,
            w11 * fx,
        ],
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kernel::VolumeView;
    use glam::Vec3;
    use radiance_volume::{sample::sample_into, Aabb, GridDims, VoxelGrid};

    /// The kernel's rule equals radiance-volume's reference rule, including clamped edges, the
    /// box faces and points outside.
    #[test]
    fn matches_radiance_volume_rule() {
        let dims = GridDims::new(2, 3, 4);
        let grid = VoxelGrid::new(Aabb::CUBE, dims).unwrap();
        let planar: Vec<f32> = (0..4 * dims.voxel_count())
            .map(|i| ((i * 37) % 11) as f32 * 0.1)
            .collect();
        let v = dims.voxel_count();
        let interleaved: Vec<[f32; 4]> = (0..v)
            .map(|i| {
                [
                    planar[i],
                    planar[v + i],
                    planar[2 * v + i],
                    planar[3 * v + i],
                ]
            })
            .collect();
        let view = VolumeView {
            data: &interleaved,
            n: [4, 3, 2],
            post_activation: None,
        };
        let mut expected = [0f32; 4];
        for p in [
            Vec3::new(0.1, -0.3, 0.77),
            Vec3::new(-0.99, 0.99, -0.2),
            Vec3::new(1.0, 1.0, 1.0),
            Vec3::new(-1.0, 0.0, 1.0),
            Vec3::new(1.01, 0.0, 0.0),
            Vec3::new(0.3, 0.2, -1.2),
        ] {
            sample_into(&planar, &grid, p, &mut expected);
            let u = grid.world_to_index(p);
            let got = corners(view.n, u.to_array()).map_or([0.0; 4], |c| {
                let mut acc = [0.0; 4];
                for k in 0..8 {
                    for ch in 0..4 {
                        acc[ch] += c.w[k] * view.data[c.idx[k]][ch];
                    }
                }
                acc
            });
            for ch in 0..4 {
                assert!(
                    (got[ch] - expected[ch]).abs() < 1e-5,
                    "{p}: {got:?} vs {expected:?}"
                );
            }
        }
    }

    #[test]
    fn weights_sum_to_one() {
        let c = corners::<f64>([3, 1, 2], [1.3, 0.0, 0.25]).unwrap();
        assert!((c.w.iter().sum::<f64>() - 1.0).abs() < 1e-15);
    }
}

//! Occupancy never marks a cell empty where a sample can have non-zero density.

use candle_core::{Device, Tensor};
use glam::Vec3;
use proptest::prelude::*;
use radiance_volume::{Aabb, GridDims, OccupancyGrid, RadianceVolume};

/// A volume with density only at the listed voxels.
fn sparse_volume(dims: GridDims, occupied: &[(usize, usize, usize, f32)]) -> RadianceVolume {
    let mut values = vec![0f32; 4 * dims.voxel_count()];
    for &(z, y, x, s) in occupied {
        values[dims.index(z % dims.d, y % dims.h, x % dims.w)] = s;
    }
    let t = Tensor::from_vec(values, (4, dims.d, dims.h, dims.w), &Device::Cpu).unwrap();
    RadianceVolume::new(t, Aabb::CUBE).unwrap()
}

prop_compose! {
    /// A small grid with density at up to 5 voxels (coordinates wrap around the grid), and a
    /// cell size.
    fn sparse_case()(
        d in 1usize..14, h in 1usize..14, w in 1usize..14,
        k in 1usize..6,
        occupied in proptest::collection::vec((0usize..14, 0usize..14, 0usize..14, 1e-6f32..5.0), 0..6),
    ) -> (GridDims, Vec<(usize, usize, usize, f32)>, usize) {
        (GridDims::new(d, h, w), occupied, k)
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]
    #[test]
    fn no_sample_with_density_lies_in_an_empty_cell(
        (dims, occupied, k) in sparse_case(),
        probes in proptest::collection::vec((-1.0f32..=1.0, -1.0f32..=1.0, -1.0f32..=1.0), 200),
    ) {
        let (d, h, w) = (dims.d, dims.h, dims.w);
        let v = sparse_volume(dims, &occupied);
        let occ = OccupancyGrid::build(&v, k, 0.0).unwrap();
        prop_assert_eq!(occ.dims(), GridDims::new(d.div_ceil(k), h.div_ceil(k), w.div_ceil(k)));
        // Random points, plus points on and next to every cell border along each axis.
        let g = *v.grid();
        let mut points: Vec<Vec3> = probes.iter().map(|&(x, y, z)| Vec3::new(x, y, z)).collect();
        for &(z, y, x, _) in &occupied {
            let c = g.cell_center(z % d, y % h, x % w);
            for off in [-1.5f32, -1.0, -0.5, 0.0, 0.5, 1.0, 1.5] {
                for axis in 0..3 {
                    let mut p = c;
                    p[axis] += off * g.voxel_size()[axis];
                    points.push(p);
                }
            }
        }
        for p in points {
            let sigma = v.sample(p).unwrap()[0];
            if sigma != 0.0 {
                prop_assert!(occ.is_occupied_at(p), "density {} at {} in an empty cell", sigma, p);
            }
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(32))]
    /// A cell is occupied exactly when a voxel of its footprint (its voxels and one more on each
    /// side, clipped to the grid) holds density.
    #[test]
    fn cells_are_occupied_exactly_when_their_footprint_holds_density((dims, occupied, k) in sparse_case()) {
        let (d, h, w) = (dims.d, dims.h, dims.w);
        let v = sparse_volume(dims, &occupied);
        let occ = OccupancyGrid::build(&v, k, 0.0).unwrap();
        let dense: Vec<(usize, usize, usize)> =
            occupied.iter().map(|&(z, y, x, _)| (z % d, y % h, x % w)).collect();
        let reaches = |voxel: usize, cell: usize| voxel + 1 >= cell * k && voxel <= (cell + 1) * k;
        let cells = occ.dims();
        for cz in 0..cells.d {
            for cy in 0..cells.h {
                for cx in 0..cells.w {
                    let expected = dense
                        .iter()
                        .any(|&(z, y, x)| reaches(z, cz) && reaches(y, cy) && reaches(x, cx));
                    prop_assert_eq!(occ.is_occupied(cz, cy, cx), expected, "cell ({}, {}, {})", cz, cy, cx);
                }
            }
        }
    }
}

#[test]
fn empty_volume_has_no_occupied_cells_and_full_volume_all() {
    let empty = sparse_volume(GridDims::cube(16), &[]);
    assert_eq!(
        OccupancyGrid::build(&empty, 4, 0.0)
            .unwrap()
            .occupied_fraction(),
        0.0
    );
    let full =
        RadianceVolume::from_fn(GridDims::cube(16), Aabb::CUBE, 4, |_, o| o[0] = 1.0).unwrap();
    assert_eq!(
        OccupancyGrid::build(&full, 4, 0.0)
            .unwrap()
            .occupied_fraction(),
        1.0
    );
}

#[test]
fn a_voxel_on_a_block_border_marks_the_neighbouring_cell() {
    // Voxel x = 7 is the last of cell 0 (k = 8); trilinear samples in cell 1 up to centre 8 read it.
    let v = sparse_volume(GridDims::new(1, 1, 24), &[(0, 0, 7, 1.0)]);
    let occ = OccupancyGrid::build(&v, 8, 0.0).unwrap();
    assert!(occ.is_occupied(0, 0, 0));
    assert!(occ.is_occupied(0, 0, 1));
    assert!(!occ.is_occupied(0, 0, 2));
}

#[test]
fn threshold_bounds_the_density_of_empty_cells() {
    let v = RadianceVolume::from_fn(GridDims::cube(16), Aabb::CUBE, 4, |p, o| {
        o[0] = (1.0 - p.length()).max(0.0);
    })
    .unwrap();
    let tau = 0.3;
    let occ = OccupancyGrid::build(&v, 4, tau).unwrap();
    for i in 0..2000 {
        let t = i as f32 * 0.618;
        let p = Vec3::new(t.sin(), (1.3 * t).cos(), (0.7 * t).sin() * 0.99);
        if !occ.is_occupied_at(p) {
            assert!(v.sample(p).unwrap()[0] <= tau);
        }
    }
    assert!(occ.occupied_fraction() > 0.0 && occ.occupied_fraction() < 1.0);
}

#[test]
fn nan_density_counts_as_occupied_and_bad_arguments_fail() {
    let v = sparse_volume(GridDims::cube(8), &[(1, 1, 1, f32::NAN)]);
    let occ = OccupancyGrid::build(&v, 4, 0.0).unwrap();
    assert!(occ.is_occupied(0, 0, 0));
    assert!(OccupancyGrid::build(&v, 0, 0.0).is_err());
    assert!(OccupancyGrid::build(&v, 4, -1.0).is_err());
}

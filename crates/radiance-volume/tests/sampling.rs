//! Trilinear sampling: exact values at centres, linear blends between them, the edge-clamp and
//! zero-outside rules, and agreement with a float64 reference on random grids.

use candle_core::{Device, Tensor};
use glam::Vec3;
use proptest::prelude::*;
use radiance_volume::{Aabb, GridDims, RadianceVolume, VoxelGrid};

/// A 4-channel volume whose value at voxel (z, y, x), channel c, is a distinct integer.
fn counting_volume(dims: GridDims, aabb: Aabb) -> RadianceVolume {
    let n = 4 * dims.voxel_count();
    let values: Vec<f32> = (0..n).map(|i| i as f32).collect();
    let t = Tensor::from_vec(values, (4, dims.d, dims.h, dims.w), &Device::Cpu).unwrap();
    RadianceVolume::new(t, aabb).unwrap()
}

fn value_at(dims: GridDims, c: usize, z: usize, y: usize, x: usize) -> f32 {
    (c * dims.voxel_count() + dims.index(z, y, x)) as f32
}

#[test]
fn cell_centres_return_exact_voxel_values() {
    let dims = GridDims::new(3, 4, 5);
    let aabb = Aabb::try_new(Vec3::new(-1.0, 0.0, 2.0), Vec3::new(1.5, 3.0, 2.5)).unwrap();
    let v = counting_volume(dims, aabb);
    for z in 0..dims.d {
        for y in 0..dims.h {
            for x in 0..dims.w {
                let s = v.sample(v.grid().cell_center(z, y, x)).unwrap();
                for (c, &got) in s.iter().enumerate() {
                    assert_eq!(
                        got,
                        value_at(dims, c, z, y, x),
                        "voxel ({z},{y},{x}) channel {c}"
                    );
                }
            }
        }
    }
}

#[test]
fn cell_centre_positions_follow_the_convention() {
    // n cells over [min, max]: centre i at min + (i + 0.5) * (max - min) / n.
    let g = VoxelGrid::new(
        Aabb::try_new(Vec3::new(0.0, -2.0, 1.0), Vec3::new(4.0, 2.0, 2.0)).unwrap(),
        GridDims::new(2, 8, 4),
    )
    .unwrap();
    assert_eq!(g.cell_center(0, 0, 0), Vec3::new(0.5, -1.75, 1.25));
    assert_eq!(g.cell_center(1, 7, 3), Vec3::new(3.5, 1.75, 1.75));
    assert_eq!(g.world_to_index(Vec3::new(0.5, -1.75, 1.25)), Vec3::ZERO);
}

#[test]
fn midway_between_centres_is_the_average() {
    let dims = GridDims::cube(4);
    let v = counting_volume(dims, Aabb::CUBE);
    let g = *v.grid();
    // Halfway along x, then a quarter along y: linear blends per axis.
    let a = g.cell_center(1, 1, 1);
    let b = g.cell_center(1, 1, 2);
    let s = v.sample((a + b) * 0.5).unwrap();
    assert_eq!(
        s[0],
        0.5 * (value_at(dims, 0, 1, 1, 1) + value_at(dims, 0, 1, 1, 2))
    );
    let p = g.index_to_world(Vec3::new(1.0, 1.25, 1.0));
    let s = v.sample(p).unwrap();
    let expected = 0.75 * value_at(dims, 2, 1, 1, 1) + 0.25 * value_at(dims, 2, 1, 2, 1);
    assert!((s[2] - expected).abs() < 1e-4, "{} vs {expected}", s[2]);
}

#[test]
fn beyond_outermost_centres_values_clamp_to_the_edge() {
    let dims = GridDims::cube(4);
    let v = counting_volume(dims, Aabb::CUBE);
    // Box face x = -1 is half a cell beyond centre 0 (at -0.75).
    let g = *v.grid();
    let centre = g.cell_center(2, 1, 0);
    let on_face = Vec3::new(-1.0, centre.y, centre.z);
    assert_eq!(v.sample(on_face).unwrap(), v.sample(centre).unwrap());
    let corner = v.sample(Vec3::splat(1.0)).unwrap();
    assert_eq!(corner[0], value_at(dims, 0, 3, 3, 3));
}

#[test]
fn outside_the_box_every_channel_is_zero() {
    let v = counting_volume(GridDims::cube(3), Aabb::CUBE);
    for p in [
        Vec3::new(1.0001, 0.0, 0.0),
        Vec3::new(0.0, -1.5, 0.0),
        Vec3::splat(9.0),
    ] {
        assert!(v.sample(p).unwrap().iter().all(|&s| s == 0.0), "at {p}");
    }
}

#[test]
fn single_voxel_volume_is_constant_inside() {
    let v = counting_volume(GridDims::cube(1), Aabb::CUBE);
    for p in [Vec3::ZERO, Vec3::splat(0.99), Vec3::new(-1.0, 1.0, 0.3)] {
        assert_eq!(v.sample(p).unwrap(), vec![0.0, 1.0, 2.0, 3.0]);
    }
}

/// Trilinear interpolation computed independently in float64 from the definition.
fn reference_sample(values: &[f32], dims: GridDims, aabb: Aabb, p: [f64; 3], c: usize) -> f64 {
    let n = [dims.w, dims.h, dims.d];
    let mut idx = [(0usize, 0usize, 0f64); 3];
    for a in 0..3 {
        let (lo, hi) = (f64::from(aabb.min[a]), f64::from(aabb.max[a]));
        let u = (p[a] - lo) / (hi - lo) * n[a] as f64 - 0.5;
        let u = u.clamp(0.0, (n[a] - 1) as f64);
        let i0 = u.floor() as usize;
        let i1 = (i0 + 1).min(n[a] - 1);
        idx[a] = (i0, i1, u - i0 as f64);
    }
    let mut acc = 0.0;
    for corner in 0..8 {
        let pick = |a: usize| {
            let (i0, i1, t) = idx[a];
            if corner >> a & 1 == 1 {
                (i1, t)
            } else {
                (i0, 1.0 - t)
            }
        };
        let ((x, wx), (y, wy), (z, wz)) = (pick(0), pick(1), pick(2));
        acc += wx * wy * wz * f64::from(values[c * dims.voxel_count() + dims.index(z, y, x)]);
    }
    acc
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]
    #[test]
    fn batch_sampling_matches_a_float64_reference(
        d in 1usize..5, h in 1usize..5, w in 1usize..5,
        seed_values in proptest::collection::vec(-10.0f32..10.0, 4 * 64),
        points in proptest::collection::vec((-1.0f64..1.0, -1.0f64..1.0, -1.0f64..1.0), 1..20),
    ) {
        let dims = GridDims::new(d, h, w);
        let values: Vec<f32> = seed_values.iter().cycle().take(4 * dims.voxel_count()).copied().collect();
        let t = Tensor::from_vec(values.clone(), (4, d, h, w), &Device::Cpu).unwrap();
        let v = RadianceVolume::new(t, Aabb::CUBE).unwrap();
        let pts: Vec<Vec3> = points.iter().map(|&(x, y, z)| Vec3::new(x as f32, y as f32, z as f32)).collect();
        let batch: Vec<Vec<f32>> = v.sample_batch(&pts).unwrap().to_vec2().unwrap();
        for (p, row) in pts.iter().zip(&batch) {
            prop_assert_eq!(row, &v.sample(*p).unwrap());
            for (c, &got) in row.iter().enumerate() {
                let want = reference_sample(&values, dims, Aabb::CUBE, [f64::from(p.x), f64::from(p.y), f64::from(p.z)], c);
                prop_assert!((f64::from(got) - want).abs() <= 1e-4 * (1.0 + want.abs()), "{} vs {}", got, want);
            }
        }
    }
}

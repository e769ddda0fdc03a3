//! Crop, paste, masks and the paper's edit primitives.

use candle_core::{DType, Device, Tensor};
use glam::Vec3;
use radiance_volume::{Aabb, GridDims, RadianceVolume, VoxelRange};

fn numbered(dims: GridDims) -> RadianceVolume {
    let n = 4 * dims.voxel_count();
    let t = Tensor::from_vec(
        (0..n).map(|i| i as f32).collect::<Vec<_>>(),
        (4, dims.d, dims.h, dims.w),
        &Device::Cpu,
    )
    .unwrap();
    RadianceVolume::new(t, Aabb::CUBE).unwrap()
}

fn values(v: &RadianceVolume) -> Vec<f32> {
    v.tensor().flatten_all().unwrap().to_vec1().unwrap()
}

#[test]
fn crop_keeps_values_and_world_positions() {
    let v = numbered(GridDims::cube(8));
    let range = VoxelRange::new(2..5, 0..8, 6..8);
    let c = v.crop(&range).unwrap();
    assert_eq!(c.dims(), GridDims::new(3, 8, 2));
    // Every cropped cell centre samples to the same value in both volumes.
    for z in 0..3 {
        for x in 0..2 {
            let p = c.grid().cell_center(z, 4, x);
            assert_eq!(c.sample(p).unwrap(), v.sample(p).unwrap());
        }
    }
    assert_eq!(c.aabb().min, Vec3::new(0.5, -1.0, -0.5));
    assert_eq!(c.aabb().max, Vec3::new(1.0, 1.0, 0.25));
    assert!(v.crop(&VoxelRange::new(2..9, 0..1, 0..1)).is_err());
    assert!(v.crop(&VoxelRange::new(2..2, 0..1, 0..1)).is_err());
}

#[test]
fn paste_then_crop_returns_the_pasted_block() {
    let big = numbered(GridDims::cube(6));
    let small = RadianceVolume::from_fn(GridDims::new(2, 3, 1), Aabb::CUBE, 4, |_, o| o.fill(-7.0))
        .unwrap();
    let pasted = big.paste(&small, [1, 2, 5]).unwrap();
    let back = pasted.crop(&VoxelRange::new(1..3, 2..5, 5..6)).unwrap();
    assert!(values(&back).iter().all(|&x| x == -7.0));
    // Everything else is untouched.
    let (a, b) = (values(&big), values(&pasted));
    let changed = a.iter().zip(&b).filter(|(x, y)| x != y).count();
    assert_eq!(changed, 4 * 2 * 3);
    assert!(big.paste(&small, [5, 0, 0]).is_err());
}

#[test]
fn removal_fills_exactly_the_masked_cells() {
    let v = numbered(GridDims::cube(4));
    let mask = v
        .box_mask(Aabb::try_new(Vec3::new(-1.0, -1.0, -1.0), Vec3::new(0.0, 0.0, 0.0)).unwrap())
        .unwrap();
    let m: Vec<f32> = mask.flatten_all().unwrap().to_vec1().unwrap();
    assert_eq!(m.iter().sum::<f32>(), 8.0);
    let empty = [0.0, 0.1, 0.2, 0.3];
    let removed = v.fill_masked(&mask, &empty).unwrap();
    let (before, after) = (values(&v), values(&removed));
    let n = 64;
    for c in 0..4 {
        for i in 0..n {
            let want = if m[i] == 1.0 {
                empty[c]
            } else {
                before[c * n + i]
            };
            assert_eq!(after[c * n + i], want);
        }
    }
    assert!(v.fill_masked(&mask, &[0.0]).is_err());
    assert!(v
        .fill_masked(
            &Tensor::zeros((4, 4), candle_core::DType::F32, &Device::Cpu).unwrap(),
            &empty
        )
        .is_err());
}

#[test]
fn duplicate_and_move_copy_the_masked_region() {
    let dims = GridDims::cube(6);
    let v = numbered(dims);
    // Mask the single voxel (1, 1, 1) and move it by (+2, 0, +3).
    let mut m = vec![0f32; dims.voxel_count()];
    m[dims.index(1, 1, 1)] = 1.0;
    let mask = Tensor::from_vec(m, (6, 6, 6), &Device::Cpu).unwrap();
    let src = dims.index(1, 1, 1);
    let dst = dims.index(3, 1, 4);
    let before = values(&v);

    let dup = values(&v.translate_masked(&mask, [2, 0, 3], None).unwrap());
    let empty = [0.0, 0.0, 0.0, 0.0];
    let moved = values(&v.translate_masked(&mask, [2, 0, 3], Some(&empty)).unwrap());
    let n = dims.voxel_count();
    for c in 0..4 {
        assert_eq!(dup[c * n + dst], before[c * n + src]);
        assert_eq!(dup[c * n + src], before[c * n + src]);
        assert_eq!(moved[c * n + dst], before[c * n + src]);
        assert_eq!(moved[c * n + src], 0.0);
    }
    let changed = before.iter().zip(&moved).filter(|(a, b)| a != b).count();
    assert_eq!(changed, 8);
    // Shifting everything out of the grid drops it.
    let gone = values(&v.translate_masked(&mask, [0, 0, 9], Some(&empty)).unwrap());
    assert_eq!(gone[src], 0.0);
}

#[test]
fn paste_masked_puts_another_volumes_region_in_place() {
    let dims = GridDims::cube(6);
    let source = numbered(dims);
    let zeros = Tensor::zeros((4, 6, 6, 6), DType::F32, &Device::Cpu).unwrap();
    let base = RadianceVolume::new(zeros, Aabb::CUBE).unwrap();
    let mut m = vec![0f32; dims.voxel_count()];
    m[dims.index(1, 1, 1)] = 1.0;
    m[dims.index(1, 2, 1)] = 1.0;
    let mask = Tensor::from_vec(m, (6, 6, 6), &Device::Cpu).unwrap();
    let pasted = values(&base.paste_masked(&source, &mask, [0, 3, -1]).unwrap());
    let from = values(&source);
    let n = dims.voxel_count();
    for c in 0..4 {
        assert_eq!(
            pasted[c * n + dims.index(1, 4, 0)],
            from[c * n + dims.index(1, 1, 1)]
        );
        assert_eq!(
            pasted[c * n + dims.index(1, 5, 0)],
            from[c * n + dims.index(1, 2, 1)]
        );
    }
    // Everything else stays the base's.
    assert_eq!(pasted.iter().filter(|v| **v != 0.0).count(), 8);
    // With the volume itself as its source, pasting is translate_masked's duplicate.
    let own = values(&source.paste_masked(&source, &mask, [0, 3, -1]).unwrap());
    let dup = values(&source.translate_masked(&mask, [0, 3, -1], None).unwrap());
    assert_eq!(own, dup);
    // A source on another grid is refused.
    let small = numbered(GridDims::cube(4));
    let err = base.paste_masked(&small, &mask, [0, 0, 0]).unwrap_err();
    assert!(err.to_string().contains("same shape"), "{err}");
}

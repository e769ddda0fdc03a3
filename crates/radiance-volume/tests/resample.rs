//! Resampling keeps constant fields, and linear fields where the convention says it must.

use glam::Vec3;
use radiance_volume::{resample_tensor, Aabb, GridDims, RadianceVolume};

fn linear(p: Vec3) -> f32 {
    0.3 * p.x - 0.7 * p.y + 0.2 * p.z + 1.0
}

fn linear_volume(dims: GridDims) -> RadianceVolume {
    RadianceVolume::from_fn(dims, Aabb::CUBE, 4, |p, out| {
        out.copy_from_slice(&[linear(p), 2.0 * linear(p), 0.5, -1.0]);
    })
    .unwrap()
}

#[test]
fn constant_fields_survive_up_and_down_sampling() {
    let v = RadianceVolume::from_fn(GridDims::new(9, 7, 5), Aabb::CUBE, 5, |_, out| {
        out.copy_from_slice(&[2.0, 0.25, 0.5, 0.75, -3.0]);
    })
    .unwrap();
    for dims in [
        GridDims::new(12, 9, 7),
        GridDims::new(4, 3, 2),
        GridDims::cube(1),
    ] {
        let r = v.resample(dims).unwrap();
        assert_eq!(r.dims(), dims);
        let vals: Vec<f32> = r.tensor().flatten_all().unwrap().to_vec1().unwrap();
        for (i, &x) in vals.iter().enumerate() {
            let want = [2.0, 0.25, 0.5, 0.75, -3.0][i / dims.voxel_count()];
            assert!((x - want).abs() < 1e-6, "{x} vs {want}");
        }
    }
}

#[test]
fn linear_fields_survive_downsampling_exactly() {
    let v = linear_volume(GridDims::new(40, 32, 24));
    let down = v.rescale(0.75).unwrap();
    assert_eq!(down.dims(), GridDims::new(30, 24, 18));
    let g = *down.grid();
    let vals: Vec<f32> = down.tensor().flatten_all().unwrap().to_vec1().unwrap();
    let n = g.dims.voxel_count();
    for z in 0..g.dims.d {
        for y in 0..g.dims.h {
            for x in 0..g.dims.w {
                let want = linear(g.cell_center(z, y, x));
                let got = vals[g.dims.index(z, y, x)];
                assert!((got - want).abs() < 1e-4, "({z},{y},{x}): {got} vs {want}");
                assert!((vals[n + g.dims.index(z, y, x)] - 2.0 * want).abs() < 2e-4);
            }
        }
    }
}

#[test]
fn linear_fields_survive_upsampling_inside_the_old_centres() {
    let coarse = linear_volume(GridDims::cube(30));
    let fine = coarse.rescale(4.0 / 3.0).unwrap();
    assert_eq!(fine.dims(), GridDims::cube(40));
    let (cg, fg) = (*coarse.grid(), *fine.grid());
    let hull_lo = cg.cell_center(0, 0, 0);
    let hull_hi = cg.cell_center(29, 29, 29);
    let vals: Vec<f32> = fine.tensor().flatten_all().unwrap().to_vec1().unwrap();
    let mut checked = 0;
    for z in 0..40 {
        for y in 0..40 {
            for x in 0..40 {
                let p = fg.cell_center(z, y, x);
                let got = vals[fg.dims.index(z, y, x)];
                if p.cmpge(hull_lo).all() && p.cmple(hull_hi).all() {
                    assert!((got - linear(p)).abs() < 1e-4, "inside hull at {p}: {got}");
                    checked += 1;
                } else {
                    // Beyond the hull the value is the clamped one: the sample at the nearest
                    // point of the hull.
                    let q = p.clamp(hull_lo, hull_hi);
                    assert!(
                        (got - linear(q)).abs() < 1e-4,
                        "edge at {p}: {got} vs {}",
                        linear(q)
                    );
                }
            }
        }
    }
    assert!(checked > 30 * 30 * 30);
}

#[test]
fn resampling_batched_tensors_matches_per_volume_resampling() {
    let a = linear_volume(GridDims::cube(6));
    let batch = candle_core::Tensor::stack(&[a.tensor(), &(a.tensor() * 2.0).unwrap()], 0).unwrap();
    let r = resample_tensor(&batch, GridDims::new(8, 5, 3)).unwrap();
    assert_eq!(r.dims(), &[2, 4, 8, 5, 3]);
    let single = a.resample(GridDims::new(8, 5, 3)).unwrap();
    let diff = (r.get(0).unwrap() - single.tensor())
        .unwrap()
        .abs()
        .unwrap()
        .max_all()
        .unwrap();
    assert_eq!(diff.to_scalar::<f32>().unwrap(), 0.0);
}

#[test]
fn bad_resample_arguments_are_errors() {
    let v = linear_volume(GridDims::cube(4));
    assert!(v.resample(GridDims::new(0, 4, 4)).is_err());
    assert!(v.rescale(0.0).is_err());
    assert!(v.rescale(f32::NAN).is_err());
}

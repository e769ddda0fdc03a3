//! Stability under extreme inputs: outputs and gradients stay finite, opacity in [0, 1]; bad
//! volumes are rejected with a clear error.

mod common;

use candle_core::{DType, Device, Tensor, Var};
use volrender::{render, Error, RenderConfig, Sampler};

use common::{mixed_rays, rng, values};

fn constant_volume(dims: (usize, usize, usize), sigma: f32, dtype: DType) -> Tensor {
    let (d, h, w) = dims;
    let s = Tensor::full(sigma, (1, d, h, w), &Device::Cpu).unwrap();
    let c = Tensor::full(0.7f32, (3, d, h, w), &Device::Cpu).unwrap();
    Tensor::cat(&[s, c], 0).unwrap().to_dtype(dtype).unwrap()
}

/// Renders with every output, backpropagates a loss touching all of them, and checks finiteness
/// and the opacity range; returns (rgb, opacity).
fn render_and_check(vol: &Tensor, sampler: Sampler) -> (Vec<f64>, Vec<f64>) {
    let rays = mixed_rays(&mut rng(1), 8);
    let cfg = RenderConfig::default()
        .with_sampler(sampler)
        .with_depth(true)
        .with_opacity(true)
        .with_background([0.2, 0.2, 0.2]);
    let var = Var::from_tensor(vol).unwrap();
    let out = render(var.as_tensor(), &rays, &cfg).unwrap();
    let (rgb, depth, opacity) = (
        values(&out.rgb),
        values(out.depth.as_ref().unwrap()),
        values(out.opacity.as_ref().unwrap()),
    );
    assert!(
        rgb.iter().chain(&depth).all(|x| x.is_finite()),
        "non-finite output"
    );
    assert!(
        opacity.iter().all(|a| (0.0..=1.0).contains(a)),
        "opacity out of [0, 1]: {opacity:?}"
    );
    let loss = (out.rgb.sum_all().unwrap()
        + out.depth.unwrap().sum_all().unwrap()
        + out.opacity.unwrap().sum_all().unwrap())
    .unwrap();
    let grad = values(loss.backward().unwrap().get(&var).unwrap());
    assert!(grad.iter().all(|g| g.is_finite()), "non-finite gradient");
    (rgb, opacity)
}

#[test]
fn extreme_densities_stay_finite() {
    for dtype in [DType::F32, DType::F64] {
        for sigma in [0.0, 1e-12, 1e6, 1e30, f32::MAX] {
            for sampler in [
                Sampler::Uniform { samples: 16 },
                Sampler::PerVoxel { per_voxel: 3 },
            ] {
                let (rgb, opacity) =
                    render_and_check(&constant_volume((4, 3, 5), sigma, dtype), sampler);
                // Ray 0 (generic) goes through the box.
                if sigma == 0.0 {
                    assert_eq!(opacity[0], 0.0);
                    assert!(
                        (rgb[0] - 0.2).abs() < 1e-7,
                        "background shows through empty space"
                    );
                }
                if sigma >= 1e6 {
                    assert!((opacity[0] - 1.0).abs() < 1e-6);
                    assert!(
                        (rgb[0] - 0.7).abs() < 1e-6,
                        "an opaque volume shows its colour"
                    );
                }
                if sigma == 1e-12 && dtype == DType::F64 {
                    assert!(opacity[0] > 0.0 && opacity[0] < 1e-11);
                }
            }
        }
    }
}

#[test]
fn tiny_grids_stay_finite() {
    for dims in [(1, 1, 1), (1, 1, 7), (7, 1, 1), (1, 5, 1)] {
        for sigma in [0.0, 2.0, 1e30] {
            render_and_check(
                &constant_volume(dims, sigma, DType::F32),
                Sampler::Uniform { samples: 5 },
            );
        }
    }
}

#[test]
fn a_zero_length_segment_renders_nothing() {
    let rays = volrender::Rays::new(vec![[0.0, 2.0, 0.5]], vec![[1.0, -1.0, 0.0]]).unwrap();
    let vol = constant_volume((2, 2, 2), 5.0, DType::F64);
    let cfg = RenderConfig::default().with_opacity(true);
    let var = Var::from_tensor(&vol).unwrap();
    let out = render(var.as_tensor(), &rays, &cfg).unwrap();
    assert_eq!(values(out.opacity.as_ref().unwrap()), vec![0.0]);
    let g = values(
        out.opacity
            .unwrap()
            .sum_all()
            .unwrap()
            .backward()
            .unwrap()
            .get(&var)
            .unwrap(),
    );
    assert!(g.iter().all(|&x| x == 0.0));
}

#[test]
fn bad_volumes_are_rejected_with_their_location() {
    let rays = mixed_rays(&mut rng(2), 0);
    let cfg = RenderConfig::default();
    let base: Vec<f32> = constant_volume((2, 3, 4), 1.0, DType::F32)
        .flatten_all()
        .unwrap()
        .to_vec1()
        .unwrap();
    for (at, value, what) in [
        (5, f32::NAN, "NaN"),
        (30, f32::INFINITY, "inf"),
        (7, -1.0, "-1"),
    ] {
        let mut v = base.clone();
        v[at] = value;
        let vol = Tensor::from_vec(v, (4, 2, 3, 4), &Device::Cpu).unwrap();
        match render(&vol, &rays, &cfg) {
            Err(Error::InvalidVolume {
                count: 1, first, ..
            }) => {
                assert!(first.contains(what), "{first}");
                assert!(first.contains("voxel"), "{first}");
            }
            other => panic!("expected InvalidVolume for {what}, got {other:?}"),
        }
    }
}

#[test]
fn bad_arguments_are_rejected() {
    let rays = mixed_rays(&mut rng(2), 0);
    let vol = constant_volume((2, 2, 2), 1.0, DType::F32);
    let bad = |cfg: RenderConfig| render(&vol, &rays, &cfg).is_err();
    assert!(bad(
        RenderConfig::default().with_sampler(Sampler::Uniform { samples: 0 })
    ));
    // More samples per ray than f32 sample positions can tell apart, directly or through a
    // per-voxel count (2x2x2 grid: the diagonal crosses sqrt(12) voxel edges).
    let too_many = volrender::MAX_SAMPLES_PER_RAY + 1;
    let message = |cfg: RenderConfig| render(&vol, &rays, &cfg).unwrap_err().to_string();
    assert!(
        message(RenderConfig::default().with_sampler(Sampler::Uniform { samples: too_many }))
            .contains("sampler")
    );
    assert!(
        message(RenderConfig::default().with_sampler(Sampler::PerVoxel {
            per_voxel: too_many / 3
        }))
        .contains("samples per ray on this grid")
    );
    assert!(bad(RenderConfig::default().with_epsilon(1.5)));
    assert!(bad(RenderConfig::default().with_background([
        f32::NAN,
        0.0,
        0.0
    ])));
    assert!(render(
        &vol.narrow(0, 0, 3).unwrap(),
        &rays,
        &RenderConfig::default()
    )
    .is_err());
    assert!(render(
        &vol.to_dtype(DType::BF16).unwrap(),
        &rays,
        &RenderConfig::default()
    )
    .is_err());
    let batch = vol.unsqueeze(0).unwrap();
    assert!(
        volrender::render_batch(&batch, &[rays.clone(), rays], &RenderConfig::default()).is_err()
    );
}

/// Found by fuzzing (`fuzz/fuzz_targets/render.rs`): a box 1e37 wide and a ray 3.5e8 long per
/// unit of t, and then a background of -1.7e38, rendered finite images whose gradient overflowed. Such scales are now refused by
/// name, and the largest accepted ones keep outputs and gradients finite.
#[test]
fn scales_whose_gradients_would_overflow_are_refused_and_the_largest_accepted_stay_finite() {
    use radiance_volume::Aabb;
    use volrender::{Rays, MAX_COORDINATE, MAX_VOLUME_VALUE, MIN_DIRECTION_LENGTH};
    let huge = Aabb::try_new([0.0, -2.8e10, -1.7e38].into(), [2.1e37; 3].into()).unwrap();
    let cfg = RenderConfig::default().with_aabb(huge);
    let ray = Rays::new(vec![[0.0; 3]], vec![[0.0, 0.0, 1.0]]).unwrap();
    let vol = constant_volume((2, 2, 2), 1.0, DType::F32);
    let err = render(&vol, &ray, &cfg).unwrap_err().to_string();
    assert!(err.contains("aabb"), "{err}");
    let err = Rays::new(vec![[2.1e37, 0.0, 0.0]], vec![[0.0, 0.0, 1.0]]).unwrap_err();
    assert!(err.to_string().contains("origin 0"), "{err}");
    let err = Rays::new(vec![[0.0; 3]], vec![[1e-6, 0.0, 0.0]]).unwrap_err();
    assert!(err.to_string().contains("direction 0"), "{err}");
    let bright = (constant_volume((2, 2, 2), 1.0, DType::F32) * 1e20).unwrap();
    let err = render(&bright, &ray, &RenderConfig::default()).unwrap_err();
    assert!(matches!(err, Error::InvalidVolume { .. }), "{err}");
    // The second find: a background of -1.7e38.
    let dark = RenderConfig::default().with_background([0.0, -1.7e38, 0.0]);
    let err = render(&vol, &ray, &dark).unwrap_err().to_string();
    assert!(err.contains("background"), "{err}");

    // The extremes that are accepted: the widest box, a far origin, the shortest direction,
    // the brightest colours, the densest density.
    let m = MAX_COORDINATE;
    let widest = Aabb::try_new([-m; 3].into(), [m; 3].into()).unwrap();
    let cfg = RenderConfig::default()
        .with_aabb(widest)
        .with_background([MAX_VOLUME_VALUE, -MAX_VOLUME_VALUE, 0.0])
        .with_depth(true)
        .with_opacity(true);
    let rays = Rays::new(
        vec![[-m, -m, -m], [0.0, 0.0, 0.0]],
        vec![[MIN_DIRECTION_LENGTH, 0.0, 0.0], [0.3, -0.2, 0.9]],
    )
    .unwrap();
    for sigma in [1e-30, 1.0, f32::MAX] {
        let s = Tensor::full(sigma, (1, 2, 2, 2), &Device::Cpu).unwrap();
        let c = Tensor::full(-1e10f32, (3, 2, 2, 2), &Device::Cpu).unwrap();
        let var = Var::from_tensor(&Tensor::cat(&[s, c], 0).unwrap()).unwrap();
        let out = render(var.as_tensor(), &rays, &cfg).unwrap();
        let (depth, opacity) = (out.depth.unwrap(), out.opacity.unwrap());
        for t in [&out.rgb, &depth, &opacity] {
            assert!(values(t).iter().all(|v| v.is_finite()), "sigma {sigma}");
        }
        let loss = (out.rgb.sum_all().unwrap() + depth.sum_all().unwrap()).unwrap();
        let grad = values(loss.backward().unwrap().get(&var).unwrap());
        assert!(
            grad.iter().all(|g| g.is_finite()),
            "sigma {sigma}: {grad:?}"
        );
    }
}

/// Post-activated density takes raw values of either sign (the physical rule refuses -1), still
/// refuses NaN and values beyond the bound, keeps outputs and gradients finite at the bound's
/// extremes (exactly empty far below the knee), and refuses options it cannot honour by name.
#[test]
fn post_activated_density_takes_raw_values_and_refuses_bad_options() {
    use volrender::DensityInterpolation;
    let rays = mixed_rays(&mut rng(4), 0);
    let post = DensityInterpolation::PostActivated {
        scale: 25.0,
        shift: -4.0,
    };
    let cfg = RenderConfig::default()
        .with_density(post)
        .with_opacity(true)
        .with_depth(true);
    let with_density = |sigma: f32| {
        let base: Vec<f32> = constant_volume((2, 3, 4), 0.5, DType::F32)
            .flatten_all()
            .unwrap()
            .to_vec1()
            .unwrap();
        let mut v = base;
        v[..24].fill(sigma);
        Tensor::from_vec(v, (4, 2, 3, 4), &Device::Cpu).unwrap()
    };
    assert!(render(&with_density(-1.0), &rays, &RenderConfig::default()).is_err());
    for raw in [-1.0, -1e10, 1e10, 0.0] {
        let var = Var::from_tensor(&with_density(raw)).unwrap();
        for skip in [false, true] {
            let out = render(var.as_tensor(), &rays, &cfg.with_skip_empty(skip)).unwrap();
            let opacity = values(out.opacity.as_ref().unwrap());
            assert!(opacity.iter().all(|a| (0.0..=1.0).contains(a)), "{raw}");
            if raw == -1e10 {
                assert!(
                    opacity.iter().all(|&a| a == 0.0),
                    "far below the knee is empty"
                );
            }
            let grads = (out.rgb.sum_all().unwrap() + out.depth.unwrap().sum_all().unwrap())
                .unwrap()
                .backward()
                .unwrap();
            let g = values(grads.get(&var).unwrap());
            assert!(g.iter().all(|x| x.is_finite()), "{raw}: {g:?}");
        }
    }
    for (raw, what) in [(f32::NAN, "NaN"), (2e10, "20000000000")] {
        let err = render(&with_density(raw), &rays, &cfg)
            .unwrap_err()
            .to_string();
        assert!(err.contains(what) && err.contains("raw density"), "{err}");
    }
    let refused = |cfg: RenderConfig| {
        render(&with_density(1.0), &rays, &cfg)
            .unwrap_err()
            .to_string()
    };
    for (scale, shift) in [
        (0.0, 0.0),
        (-1.0, 0.0),
        (1.0, f32::NAN),
        (f32::INFINITY, 0.0),
    ] {
        let message =
            refused(cfg.with_density(DensityInterpolation::PostActivated { scale, shift }));
        assert!(message.contains("density"), "{message}");
    }
}

//! The portable (candle-ops, any-device) renderer against the fused CPU kernel: values and
//! gradients in f32 to 1e-5 relative on the benchmark scenes, in f64 on random volumes (the
//! proptest in gradients.rs), chunking that does not change results, misses, and its refusals.
//!
//! Relative tolerance `rel` (1e-5 in f32): every value within `rel` of the output's largest
//! magnitude, and the relative L2 error of the whole output (or gradient) at most `rel`. (In f32
//! the measured worst cases are 6e-7 of the peak per value and 6e-7 in L2, both for the
//! gradient; in f64, 4e-16.)

mod common;

use candle_core::{DType, Device, Tensor, Var};
use volrender::portable::{render_portable, render_portable_chunked};
use volrender::scenes::{make_scene, peer_rays, Scene};
use volrender::{render, DensityInterpolation, Error, Rays, RenderConfig, Sampler};

use common::{mixed_rays, random_volume, rng, values};

fn assert_close(what: &str, portable: &[f64], kernel: &[f64], rel: f64) {
    assert_eq!(portable.len(), kernel.len(), "{what}: lengths");
    let peak = kernel.iter().fold(0f64, |m, x| m.max(x.abs()));
    for (i, (p, k)) in portable.iter().zip(kernel).enumerate() {
        assert!(
            (p - k).abs() <= rel * peak,
            "{what} {i}: portable {p} vs kernel {k} (peak {peak})"
        );
    }
    let squared = |v: &mut dyn Iterator<Item = f64>| v.map(|x| x * x).sum::<f64>();
    let error = squared(&mut portable.iter().zip(kernel).map(|(p, k)| p - k)).sqrt();
    let norm = squared(&mut kernel.iter().copied()).sqrt();
    assert!(
        error <= rel * norm,
        "{what}: relative L2 error {}",
        error / norm
    );
}

/// `sum(rgb * wr) + sum(depth * wd) + sum(opacity * wo)` with fixed pseudo-random weights, so
/// every output's gradient is checked.
fn weighted_loss(out: &volrender::RenderOutput) -> Tensor {
    let weigh = |t: &Tensor, salt: f64| {
        let n = t.elem_count();
        let w: Vec<f32> = (0..n)
            .map(|i| ((i as f64 * 0.618 + salt).fract() - 0.5) as f32)
            .collect();
        let w = Tensor::from_vec(w, t.shape(), t.device())
            .unwrap()
            .to_dtype(t.dtype())
            .unwrap();
        (t * w).unwrap().sum_all().unwrap()
    };
    let mut l = weigh(&out.rgb, 0.1);
    if let Some(d) = &out.depth {
        l = (l + weigh(d, 0.3)).unwrap();
    }
    if let Some(a) = &out.opacity {
        l = (l + weigh(a, 0.7)).unwrap();
    }
    l
}

fn scene_volume(scene: Scene, n: usize) -> Tensor {
    make_scene(scene, n, 3)
        .unwrap()
        .tensor()
        .to_dtype(DType::F32)
        .unwrap()
}

/// Renders `volume` with both paths and compares colour, depth, opacity and the gradient.
fn compare(volume: &Tensor, rays: &Rays, cfg: &RenderConfig, rel_values: f64, rel_grad: f64) {
    let var = Var::from_tensor(volume).unwrap();
    let kernel = render(var.as_tensor(), rays, cfg).unwrap();
    let portable = render_portable(var.as_tensor(), rays, cfg).unwrap();
    assert_close(
        "rgb",
        &values(&portable.rgb),
        &values(&kernel.rgb),
        rel_values,
    );
    assert_close(
        "depth",
        &values(portable.depth.as_ref().unwrap()),
        &values(kernel.depth.as_ref().unwrap()),
        rel_values,
    );
    assert_close(
        "opacity",
        &values(portable.opacity.as_ref().unwrap()),
        &values(kernel.opacity.as_ref().unwrap()),
        rel_values,
    );
    let g_kernel = values(
        weighted_loss(&kernel)
            .backward()
            .unwrap()
            .get(&var)
            .unwrap(),
    );
    let g_portable = values(
        weighted_loss(&portable)
            .backward()
            .unwrap()
            .get(&var)
            .unwrap(),
    );
    assert_close("gradient", &g_portable, &g_kernel, rel_grad);
}

fn full_outputs(sampler: Sampler) -> RenderConfig {
    RenderConfig::default()
        .with_sampler(sampler)
        .with_depth(true)
        .with_opacity(true)
        .with_background([1.0, 0.5, 0.25])
}

#[test]
fn f32_matches_the_kernel_on_the_benchmark_scenes() {
    let rays = peer_rays(576).unwrap();
    for scene in [Scene::Dense, Scene::Sparse] {
        let volume = scene_volume(scene, 24);
        for sampler in [
            Sampler::Uniform { samples: 48 },
            Sampler::UniformLeft { samples: 48 },
        ] {
            compare(&volume, &rays, &full_outputs(sampler), 1e-5, 1e-5);
        }
    }
}

#[test]
fn f32_matches_the_kernel_with_post_activated_density() {
    let rays = peer_rays(400).unwrap();
    // Raw density straddling the activation's knee: sigma in (0, 3) shifted by -1.5.
    let volume = scene_volume(Scene::Dense, 20);
    let cfg = full_outputs(Sampler::Uniform { samples: 40 }).with_density(
        DensityInterpolation::PostActivated {
            scale: 4.0,
            shift: -1.5,
        },
    );
    compare(&volume, &rays, &cfg, 1e-5, 1e-5);
}

#[test]
fn f64_matches_the_kernel_on_rays_of_every_kind() {
    // Rays from inside, grazing, along axes and missing (common::mixed_rays).
    let mut r = rng(11);
    let volume = random_volume(&mut r, [5, 4, 6], 6.0, DType::F64);
    let rays = mixed_rays(&mut r, 30);
    compare(
        &volume,
        &rays,
        &full_outputs(Sampler::Uniform { samples: 17 }),
        1e-12,
        1e-10,
    );
}

#[test]
fn chunks_do_not_change_the_result() {
    let mut r = rng(4);
    let volume = random_volume(&mut r, [6, 6, 6], 4.0, DType::F64);
    let rays = mixed_rays(&mut r, 50);
    let cfg = full_outputs(Sampler::Uniform { samples: 9 });
    let whole = render_portable_chunked(&volume, &rays, &cfg, usize::MAX).unwrap();
    // 1 ray per chunk, 3 rays per chunk, and a chunk smaller than one ray (still 1 ray).
    for chunk in [9, 27, 2] {
        let parts = render_portable_chunked(&volume, &rays, &cfg, chunk).unwrap();
        assert_close("rgb", &values(&parts.rgb), &values(&whole.rgb), 1e-14);
        assert_close(
            "depth",
            &values(parts.depth.as_ref().unwrap()),
            &values(whole.depth.as_ref().unwrap()),
            1e-14,
        );
    }
}

#[test]
fn rays_that_miss_show_the_background() {
    let volume = Tensor::ones((4, 3, 3, 3), DType::F32, &Device::Cpu).unwrap();
    let rays = Rays::new(
        vec![[0.0, 0.0, 5.0], [3.0, 3.0, 3.0]],
        vec![[0.0, 0.0, 1.0], [1.0, 0.0, 0.0]],
    )
    .unwrap();
    let out = render_portable(
        &volume,
        &rays,
        &full_outputs(Sampler::Uniform { samples: 8 }),
    )
    .unwrap();
    assert_eq!(
        out.rgb.to_vec2::<f32>().unwrap(),
        vec![vec![1.0, 0.5, 0.25]; 2]
    );
    assert_eq!(out.opacity.unwrap().to_vec1::<f32>().unwrap(), vec![0.0; 2]);
    assert_eq!(out.depth.unwrap().to_vec1::<f32>().unwrap(), vec![0.0; 2]);
}

#[test]
fn only_the_asked_outputs_are_returned() {
    let volume = Tensor::ones((4, 2, 2, 2), DType::F32, &Device::Cpu).unwrap();
    let rays = Rays::new(vec![[0.0, -3.0, 0.0]], vec![[0.0, 1.0, 0.0]]).unwrap();
    let out = render_portable(&volume, &rays, &RenderConfig::default()).unwrap();
    assert_eq!(out.rgb.dims(), &[1, 3]);
    assert!(out.depth.is_none() && out.opacity.is_none());
}

#[test]
fn bad_values_are_refused_as_the_kernel_refuses_them() {
    let rays = Rays::new(vec![[0.0, -3.0, 0.0]], vec![[0.0, 1.0, 0.0]]).unwrap();
    let cfg = RenderConfig::default();
    let mut v = vec![0.5f32; 4 * 8];
    v[8 + 5] = f32::NAN; // channel 1 (r), voxel 5 = (d=1, h=0, w=1)
    v[3] = -1.0; // channel 0 (sigma), voxel 3 = (d=0, h=1, w=1): negative density
    let volume = Tensor::from_vec(v, (4, 2, 2, 2), &Device::Cpu).unwrap();
    let kernel = render(&volume, &rays, &cfg).unwrap_err().to_string();
    let portable = render_portable(&volume, &rays, &cfg)
        .unwrap_err()
        .to_string();
    assert_eq!(portable, kernel);
    match render_portable(&volume, &rays, &cfg).unwrap_err() {
        Error::InvalidVolume { count, first, .. } => {
            assert_eq!(count, 2);
            assert!(
                first.contains("channel 0") && first.contains("(d=0, h=1, w=1)"),
                "{first}"
            );
        }
        other => panic!("expected InvalidVolume, got {other}"),
    }
    // Post-activated raw density may be negative, but an infinite colour is refused.
    let post = cfg.with_density(DensityInterpolation::PostActivated {
        scale: 1.0,
        shift: 0.0,
    });
    let mut v = vec![-2.0f32; 4 * 8];
    assert!(render_portable(
        &Tensor::from_vec(v.clone(), (4, 2, 2, 2), &Device::Cpu).unwrap(),
        &rays,
        &post
    )
    .is_ok());
    v[3 * 8] = f32::INFINITY;
    let err = render_portable(
        &Tensor::from_vec(v, (4, 2, 2, 2), &Device::Cpu).unwrap(),
        &rays,
        &post,
    )
    .unwrap_err();
    assert!(err.to_string().contains("channel 3"), "{err}");
}

#[test]
fn unsupported_options_are_refused_by_name() {
    let volume = Tensor::ones((4, 2, 2, 2), DType::F32, &Device::Cpu).unwrap();
    let rays = Rays::new(vec![[0.0, -3.0, 0.0]], vec![[0.0, 1.0, 0.0]]).unwrap();
    let per_voxel = RenderConfig::default().with_sampler(Sampler::PerVoxel { per_voxel: 2 });
    assert!(render_portable(&volume, &rays, &per_voxel)
        .unwrap_err()
        .to_string()
        .contains("sampler"));
    let err = render_portable_chunked(&volume, &rays, &RenderConfig::default(), 0).unwrap_err();
    assert!(err.to_string().contains("chunk_samples"), "{err}");
    let half = volume.to_dtype(DType::F16).unwrap();
    assert!(render_portable(&half, &rays, &RenderConfig::default())
        .unwrap_err()
        .to_string()
        .contains("F16"));
    let flat = Tensor::ones((3, 2, 2, 2), DType::F32, &Device::Cpu).unwrap();
    assert!(render_portable(&flat, &rays, &RenderConfig::default())
        .unwrap_err()
        .to_string()
        .contains("C >= 4"));
}

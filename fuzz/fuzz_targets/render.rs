//! The renderer on arbitrary small volumes (any values: NaN, negative density, huge), boxes,
//! rays (any origin and direction, zero and huge ones) and options, forward and backward.
//! It must return finite images and gradients, or an error; never panic.
#![no_main]

use arbitrary::Arbitrary;
use candle_core::{Device, Tensor, Var};
use libfuzzer_sys::fuzz_target;
use radiance_volume::Aabb;
use volgen_fuzz::all_finite;
use volrender::{render, Rays, RenderConfig, Sampler};

#[derive(Arbitrary, Debug)]
struct Input {
    dims: (u8, u8, u8),
    values: Vec<f32>,
    aabb: ([f32; 3], [f32; 3]),
    rays: Vec<([f32; 3], [f32; 3])>,
    sampler: u8,
    samples: u8,
    epsilon: f32,
    skip_empty: bool,
    background: Option<[f32; 3]>,
}

fuzz_target!(|input: Input| {
    let (d, h, w) = (
        usize::from(input.dims.0 % 6) + 1,
        usize::from(input.dims.1 % 6) + 1,
        usize::from(input.dims.2 % 6) + 1,
    );
    if input.values.is_empty() || input.rays.is_empty() || input.rays.len() > 64 {
        return;
    }
    let n = 4 * d * h * w;
    let data: Vec<f32> = input.values.iter().copied().cycle().take(n).collect();
    let volume =
        Var::from_tensor(&Tensor::from_vec(data, (4, d, h, w), &Device::Cpu).unwrap()).unwrap();
    let Ok(aabb) = Aabb::try_new(input.aabb.0.into(), input.aabb.1.into()) else {
        return;
    };
    let (origins, dirs): (Vec<_>, Vec<_>) = input.rays.iter().copied().unzip();
    let Ok(rays) = Rays::new(origins, dirs) else {
        return;
    };
    let samples = usize::from(input.samples % 32) + 1;
    let sampler = match input.sampler % 3 {
        0 => Sampler::Uniform { samples },
        1 => Sampler::UniformLeft { samples },
        _ => Sampler::PerVoxel {
            per_voxel: samples % 4 + 1,
        },
    };
    if let Sampler::PerVoxel { per_voxel } = sampler {
        // The renderer accepts up to MAX_SAMPLES_PER_RAY (2^24) samples per ray by design, so a
        // box millions of voxels long asks for millions of samples on every ray: correct, but
        // minutes under the sanitizer (a 20 s timeout, found 2026-11-25), and nothing to learn.
        let size = [0, 1, 2].map(|k| f64::from(input.aabb.1[k]) - f64::from(input.aabb.0[k]));
        let cells = [w, h, d].map(|n| n as f64);
        let voxel = (0..3)
            .map(|k| size[k] / cells[k])
            .fold(f64::INFINITY, f64::min);
        let diagonal = size.iter().map(|s| s * s).sum::<f64>().sqrt();
        if diagonal / voxel * per_voxel as f64 > 65536.0 {
            return;
        }
    }
    let mut cfg = RenderConfig::default()
        .with_sampler(sampler)
        .with_epsilon(input.epsilon)
        .with_skip_empty(input.skip_empty)
        .with_aabb(aabb)
        .with_depth(true)
        .with_opacity(true);
    if let Some(background) = input.background {
        cfg = cfg.with_background(background);
    }
    let Ok(out) = render(volume.as_tensor(), &rays, &cfg) else {
        return;
    };
    let depth = out.depth.unwrap();
    let opacity = out.opacity.unwrap();
    assert!(
        all_finite(&out.rgb) && all_finite(&depth) && all_finite(&opacity),
        "non-finite output"
    );
    let loss = (out.rgb.sum_all().unwrap() + depth.sum_all().unwrap() + opacity.sum_all().unwrap())
        .unwrap();
    let grads = loss.backward().unwrap();
    if let Some(grad) = grads.get(volume.as_tensor()) {
        assert!(all_finite(grad), "non-finite gradient");
    }
});

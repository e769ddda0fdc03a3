//! Empty-space skipping is exact; early termination stays within its bound.

mod common;

use candle_core::{DType, Var};
use proptest::prelude::*;
use volrender::{render, Camera, DensityInterpolation, Rays, RenderConfig, Sampler};

use common::{random_volume, rng, sparse_volume, values};

fn camera_rays(seed: u64, size: usize) -> Rays {
    let cam = &Camera::hemisphere(1, 3.0, 0.9, size, size, seed).unwrap()[0];
    Rays::from_camera(cam)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]

    /// Outputs are bit-identical with and without skipping; so are the colour gradients and the
    /// density gradients of voxels holding density (a skipped sample's footprint holds only
    /// empty voxels, so only empty voxels lose gradient terms). With the paper's density and
    /// with post-activated raw density, whose empty voxels are raw values far enough below the
    /// knee that their softplus is exactly 0 in f32.
    #[test]
    fn skipping_is_exact(seed in any::<u64>(), n in 4usize..14, balls in 0usize..4, cell in 1usize..6,
                         per_voxel in any::<bool>(), epsilon in prop::sample::select(vec![0.0f32, 1e-3]),
                         post_activated in any::<bool>()) {
        let mut r = rng(seed);
        let physical = sparse_volume(&mut r, n, balls, 30.0);
        let vol = if post_activated {
            let density = physical.narrow(0, 0, 1).unwrap();
            let empty = density.le(0.0).unwrap();
            let raw = empty.where_cond(&(density.ones_like().unwrap() * -200.0).unwrap(), &density).unwrap();
            candle_core::Tensor::cat(&[&raw, &physical.narrow(0, 1, 3).unwrap()], 0).unwrap()
        } else {
            physical.clone()
        };
        let rays = camera_rays(seed, 12);
        let sampler = if per_voxel { Sampler::PerVoxel { per_voxel: 2 } } else { Sampler::Uniform { samples: 37 } };
        let base = RenderConfig { occupancy_cell: cell, ..RenderConfig::default() }
            .with_sampler(sampler).with_epsilon(epsilon).with_depth(true).with_opacity(true).with_background([0.1, 0.2, 0.3]);
        let base = if post_activated {
            base.with_density(DensityInterpolation::PostActivated { scale: 2.0, shift: -1.0 })
        } else {
            base
        };
        let run = |skip: bool| {
            let var = Var::from_tensor(&vol).unwrap();
            let out = render(var.as_tensor(), &rays, &base.with_skip_empty(skip)).unwrap();
            let packed = [&out.rgb, out.depth.as_ref().unwrap(), out.opacity.as_ref().unwrap()]
                .map(|t| t.flatten_all().unwrap().to_vec1::<f32>().unwrap());
            let loss = ((out.rgb - 0.5).unwrap().sqr().unwrap().sum_all().unwrap()
                + out.depth.unwrap().sum_all().unwrap() + out.opacity.unwrap().sum_all().unwrap()).unwrap();
            let g: Vec<f32> = loss.backward().unwrap().get(&var).unwrap().flatten_all().unwrap().to_vec1().unwrap();
            (packed, g)
        };
        let (plain, g_plain) = run(false);
        let (skipped, g_skip) = run(true);
        prop_assert_eq!(plain, skipped);
        let density: Vec<f32> = physical.get(0).unwrap().flatten_all().unwrap().to_vec1().unwrap();
        let voxels = density.len();
        for (i, (a, b)) in g_plain.iter().zip(&g_skip).enumerate() {
            if i >= voxels || density[i] > 0.0 {
                prop_assert_eq!(a.to_bits(), b.to_bits(), "value {} differs", i);
            }
        }
    }

    /// Stopping at T <= epsilon changes colour and opacity by at most epsilon and depth by at
    /// most epsilon * t_exit (colours and background in [0, 1]).
    #[test]
    fn early_termination_is_bounded(seed in any::<u64>(), epsilon in prop::sample::select(vec![1e-4f32, 1e-3, 1e-2, 0.1, 0.5])) {
        let mut r = rng(seed);
        let vol = random_volume(&mut r, [6, 7, 5], 12.0, DType::F64);
        let rays = camera_rays(seed, 10);
        let cfg = RenderConfig::default().with_sampler(Sampler::Uniform { samples: 64 })
            .with_depth(true).with_opacity(true).with_background([1.0, 1.0, 0.0]);
        let exact = render(&vol, &rays, &cfg).unwrap();
        let approx = render(&vol, &rays, &cfg.with_epsilon(epsilon)).unwrap();
        let eps = epsilon as f64;
        let t_exit_max = 3.0 + 3f64.sqrt();
        let pairs = [(&exact.rgb, &approx.rgb, eps), (exact.opacity.as_ref().unwrap(), approx.opacity.as_ref().unwrap(), eps),
                     (exact.depth.as_ref().unwrap(), approx.depth.as_ref().unwrap(), eps * t_exit_max)];
        for (a, b, bound) in pairs {
            for (x, y) in values(a).iter().zip(values(b)) {
                prop_assert!((x - y).abs() <= bound * (1.0 + 1e-9), "{x} vs {y}, bound {bound}");
            }
        }
    }
}

/// With epsilon = 0 a ray stops only once its transmittance is exactly 0, so an opaque volume
/// shows exactly its first sample's colour.
#[test]
fn exact_termination_at_zero_transmittance() {
    let mut r = rng(4);
    let vol = (random_volume(&mut r, [4, 4, 4], 1.0, DType::F32) + 1e30).unwrap();
    let vol = candle_core::Tensor::cat(
        &[
            vol.narrow(0, 0, 1).unwrap(),
            vol.narrow(0, 1, 3).unwrap().affine(0.0, 0.3).unwrap(),
        ],
        0,
    )
    .unwrap();
    let rays = camera_rays(1, 6);
    let out = render(&vol, &rays, &RenderConfig::default().with_opacity(true)).unwrap();
    let opacity = values(out.opacity.as_ref().unwrap());
    let rgb = values(&out.rgb);
    for (i, &a) in opacity.iter().enumerate() {
        assert!(a == 0.0 || a == 1.0);
        if a == 1.0 {
            assert!((rgb[3 * i] - 0.3).abs() < 1e-6);
        }
    }
}

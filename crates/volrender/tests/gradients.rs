//! The backward against central finite differences in float64, per voxel, and against the
//! portable (candle-ops) path's autograd.
//!
//! Tolerance: |analytic - fd| <= 1e-6 (1 + |fd|) with step h = 1e-6 (the f64 central difference
//! of these smooth losses is accurate to about 1e-9).

mod common;

use candle_core::{DType, Device, Tensor, Var};
use proptest::prelude::*;
use volrender::portable::render_portable;
use volrender::{
    render, render_batch, DensityInterpolation, Rays, RenderConfig, RenderOutput, Sampler,
};

use common::{mixed_rays, random_volume, rng, values};

/// `sum(rgb * g_rgb) + sum(depth * g_depth) + sum(opacity * g_opacity)` in f64.
fn loss(out: &RenderOutput, weights: &[Tensor; 3]) -> Tensor {
    let mut l = (&out.rgb * &weights[0]).unwrap().sum_all().unwrap();
    if let Some(d) = &out.depth {
        l = (l + (d * &weights[1]).unwrap().sum_all().unwrap()).unwrap();
    }
    if let Some(a) = &out.opacity {
        l = (l + (a * &weights[2]).unwrap().sum_all().unwrap()).unwrap();
    }
    l
}

fn loss_weights(rays: usize, seed: u64) -> [Tensor; 3] {
    let mut r = rng(seed);
    let rgb = random_volume(&mut r, [rays, 3, 1], 1.0, DType::F64)
        .get(0)
        .unwrap()
        .reshape((rays, 3))
        .unwrap();
    let col = |t: Tensor| (t.get(1).unwrap().flatten_all().unwrap() - 0.5).unwrap();
    let extra = random_volume(&mut r, [rays, 1, 1], 1.0, DType::F64);
    let extra2 = random_volume(&mut r, [rays, 1, 1], 1.0, DType::F64);
    [(rgb - 0.5).unwrap(), col(extra), col(extra2)]
}

/// Compares the op's gradient with central differences of `f` at every value of `vol`.
fn check_fd(vol: &Tensor, f: impl Fn(&Tensor) -> f64, analytic: &[f64]) {
    let base = values(vol);
    let h = 1e-6;
    for (i, &a) in analytic.iter().enumerate() {
        let shifted = |delta: f64| {
            let mut v = base.clone();
            v[i] += delta;
            f(&Tensor::from_vec(v, vol.shape(), &Device::Cpu).unwrap())
        };
        let fd = (shifted(h) - shifted(-h)) / (2.0 * h);
        assert!(
            (a - fd).abs() <= 1e-6 * (1.0 + fd.abs()),
            "value {i}: analytic {a} vs fd {fd}"
        );
    }
}

/// The density rules: the paper's, or with `post_activated` post-activated density (whose raw
/// values then straddle the activation's knee: the random volumes' densities are >= 0 and the
/// shift is -2).
fn with_rule(cfg: RenderConfig, post_activated: bool) -> RenderConfig {
    if post_activated {
        cfg.with_density(DensityInterpolation::PostActivated {
            scale: 1.5,
            shift: -2.0,
        })
    } else {
        cfg
    }
}

fn sampler(kind: u8, n: usize) -> Sampler {
    match kind {
        0 => Sampler::Uniform { samples: n },
        1 => Sampler::UniformLeft { samples: n },
        _ => Sampler::PerVoxel {
            per_voxel: n.min(4),
        },
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]

    #[test]
    fn backward_matches_finite_differences(
        d in 1usize..4, h in 1usize..4, w in 1usize..4, seed in any::<u64>(),
        samples in 1usize..10, kind in 0u8..3, background in any::<bool>(), post_activated in any::<bool>(),
    ) {
        let mut r = rng(seed);
        let vol = random_volume(&mut r, [d, h, w], 4.0, DType::F64);
        let rays = mixed_rays(&mut r, 2);
        let cfg = RenderConfig::default()
            .with_sampler(sampler(kind, samples))
            .with_depth(true)
            .with_opacity(true);
        let mut cfg = with_rule(cfg, post_activated);
        if background {
            cfg = cfg.with_background([0.3, 0.9, 0.1]);
        }
        let weights = loss_weights(rays.len(), seed ^ 1);
        let var = Var::from_tensor(&vol).unwrap();
        let grads = loss(&render(var.as_tensor(), &rays, &cfg).unwrap(), &weights).backward().unwrap();
        let analytic = values(grads.get(&var).unwrap());
        check_fd(&vol, |v| values(&loss(&render(v, &rays, &cfg).unwrap(), &weights))[0], &analytic);
    }

    #[test]
    fn batch_backward_matches_finite_differences(seed in any::<u64>(), samples in 1usize..8) {
        let mut r = rng(seed);
        let a = random_volume(&mut r, [2, 3, 2], 3.0, DType::F64);
        let b = random_volume(&mut r, [2, 3, 2], 3.0, DType::F64);
        let vols = Tensor::stack(&[a, b], 0).unwrap();
        let rays = [mixed_rays(&mut r, 1), mixed_rays(&mut r, 3)];
        let cfg = RenderConfig::default().with_sampler(Sampler::Uniform { samples }).with_opacity(true);
        let w = [loss_weights(rays[0].len(), seed ^ 2), loss_weights(rays[1].len(), seed ^ 3)];
        let total = |v: &Tensor| {
            let outs = render_batch(v, &rays, &cfg).unwrap();
            (loss(&outs[0], &w[0]) + loss(&outs[1], &w[1])).unwrap()
        };
        let var = Var::from_tensor(&vols).unwrap();
        let analytic = values(total(var.as_tensor()).backward().unwrap().get(&var).unwrap());
        check_fd(&vols, |v| values(&total(v))[0], &analytic);
    }

    /// The fast kernel and the portable candle-ops path agree on values and gradients (f64), with
    /// both density rules.
    #[test]
    fn kernel_matches_portable(seed in any::<u64>(), samples in 1usize..12, left in any::<bool>(), post_activated in any::<bool>()) {
        let mut r = rng(seed);
        let vol = random_volume(&mut r, [3, 4, 2], 5.0, DType::F64);
        let rays = mixed_rays(&mut r, 4);
        let s = if left { Sampler::UniformLeft { samples } } else { Sampler::Uniform { samples } };
        let cfg = RenderConfig::default().with_sampler(s).with_depth(true).with_opacity(true).with_background([1.0, 0.5, 0.0]);
        let cfg = with_rule(cfg, post_activated);
        let weights = loss_weights(rays.len(), seed);
        let var = Var::from_tensor(&vol).unwrap();
        let fast = render(var.as_tensor(), &rays, &cfg).unwrap();
        let slow = render_portable(var.as_tensor(), &rays, &cfg).unwrap();
        for (a, b) in [(&fast.rgb, &slow.rgb), (fast.depth.as_ref().unwrap(), slow.depth.as_ref().unwrap()),
                       (fast.opacity.as_ref().unwrap(), slow.opacity.as_ref().unwrap())] {
            for (x, y) in values(a).iter().zip(values(b)) {
                prop_assert!((x - y).abs() < 1e-12, "{x} vs {y}");
            }
        }
        let g_fast = values(loss(&fast, &weights).backward().unwrap().get(&var).unwrap());
        let g_slow = values(loss(&slow, &weights).backward().unwrap().get(&var).unwrap());
        for (x, y) in g_fast.iter().zip(g_slow) {
            prop_assert!((x - y).abs() < 1e-10 * (1.0 + y.abs()), "{x} vs {y}");
        }
    }
}

/// The f32 kernel stays close to the f64 one (values and gradients).
#[test]
fn f32_tracks_f64() {
    let mut r = rng(5);
    let vol = random_volume(&mut r, [6, 5, 7], 8.0, DType::F64);
    let rays = mixed_rays(&mut r, 40);
    let weights = loss_weights(rays.len(), 9);
    // The paper's rule, and post-activated density (the inline exp and log of the f32 kernel's
    // softplus against f64's).
    for post_activated in [false, true] {
        let cfg = with_rule(
            RenderConfig::default()
                .with_sampler(Sampler::Uniform { samples: 64 })
                .with_depth(true),
            post_activated,
        );
        let grad = |v: &Tensor| {
            let var = Var::from_tensor(v).unwrap();
            let out = render(var.as_tensor(), &rays, &cfg).unwrap();
            let w = weights.each_ref().map(|t| t.to_dtype(v.dtype()).unwrap());
            (
                values(&out.rgb),
                values(loss(&out, &w).backward().unwrap().get(&var).unwrap()),
            )
        };
        let (c64, g64) = grad(&vol);
        let (c32, g32) = grad(&vol.to_dtype(DType::F32).unwrap());
        let scale = g64.iter().fold(0f64, |m, g| m.max(g.abs()));
        assert!(
            c64.iter().zip(&c32).all(|(a, b)| (a - b).abs() < 1e-5),
            "post-activated: {post_activated}"
        );
        assert!(
            g64.iter()
                .zip(&g32)
                .all(|(a, b)| (a - b).abs() < 1e-4 * scale),
            "post-activated: {post_activated}"
        );
    }
}

/// The same inputs give the same gradient bits, whatever the thread count (several backward
/// blocks are in use: more rays than 4 tiles of 64).
#[test]
fn gradient_bits_do_not_depend_on_threads() {
    let mut r = rng(11);
    let vol = random_volume(&mut r, [8, 8, 8], 3.0, DType::F32);
    let rays = mixed_rays(&mut r, 600);
    let cfg = RenderConfig::default()
        .with_sampler(Sampler::Uniform { samples: 32 })
        .with_opacity(true);
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| {
            let var = Var::from_tensor(&vol).unwrap();
            let out = render(var.as_tensor(), &rays, &cfg).unwrap();
            let l = (out.rgb.sqr().unwrap().sum_all().unwrap()
                + out.opacity.unwrap().sum_all().unwrap())
            .unwrap();
            let g: Vec<f32> = l
                .backward()
                .unwrap()
                .get(&var)
                .unwrap()
                .flatten_all()
                .unwrap()
                .to_vec1()
                .unwrap();
            g.iter().map(|x| x.to_bits()).collect::<Vec<u32>>()
        })
    };
    let one = run(1);
    assert_eq!(one, run(2));
    assert_eq!(one, run(3));
}

/// Rays given as non-unit directions render the same as unit ones (t is a distance).
#[test]
fn direction_length_does_not_matter() {
    let mut r = rng(3);
    let vol = random_volume(&mut r, [3, 3, 3], 2.0, DType::F64);
    let unit = Rays::new(vec![[0.1, 0.2, 3.0]], vec![[0.0, 0.0, -1.0]]).unwrap();
    let long = Rays::new(vec![[0.1, 0.2, 3.0]], vec![[0.0, 0.0, -7.5]]).unwrap();
    let cfg = RenderConfig::default().with_depth(true);
    let a = render(&vol, &unit, &cfg).unwrap();
    let b = render(&vol, &long, &cfg).unwrap();
    assert_eq!(values(&a.rgb), values(&b.rgb));
    assert_eq!(
        values(a.depth.as_ref().unwrap()),
        values(b.depth.as_ref().unwrap())
    );
}

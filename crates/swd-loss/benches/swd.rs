//! Benches of the sliced distance on point sets and of the patch-pyramid texture loss.
//!
//! `cargo bench -p swd-loss --bench swd`; numbers are recorded in docs/performance-swd.md.

use std::hint::black_box;

use candle_core::{Device, Tensor, Var};
use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal, Uniform};
use swd_loss::{
    sliced_wasserstein, Metric, PatchPyramid, PatchPyramidConfig, Points, Projections, Slices,
    TextureLoss, TextureLossConfig,
};

fn seeded_tensor<D: Distribution<f32>>(shape: &[usize], dist: D, seed: u64) -> Tensor {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let n = shape.iter().product();
    let data: Vec<f32> = dist.sample_iter(&mut rng).take(n).collect();
    Tensor::from_vec(data, shape, &Device::Cpu).unwrap()
}

/// Forward only, at the peer's bench sizes (N, C, K), so POT's timings compare directly.
fn sliced(c: &mut Criterion) {
    let mut group = c.benchmark_group("swd/sliced_fwd");
    group.sample_size(10);
    for (n, dim, k) in [(4096, 3, 128), (65536, 3, 128), (16384, 48, 128)] {
        let x = seeded_tensor(&[n, dim], StandardNormal, 1);
        let y = seeded_tensor(&[n, dim], StandardNormal, 2);
        let p =
            Projections::random(dim, k, &mut ChaCha8Rng::seed_from_u64(3), &Device::Cpu).unwrap();
        group.throughput(Throughput::Elements((n * k) as u64));
        let id = BenchmarkId::from_parameter(format!("N{n}_C{dim}_K{k}"));
        group.bench_with_input(id, &(), |b, _| {
            b.iter(|| black_box(sliced_wasserstein(&x, &y, &p, Metric::SquaredW2).unwrap()))
        });
    }
    group.finish();
}

/// The default patch pyramid (3 Laplacian levels, 7x7 patches) with 64 directions per level,
/// every patch compared (`{res}`), then at 320^2 with directions and random subsets of the
/// patches drawn at every call (`320_K{k}_P{n}`: n patches per level, k directions).
fn texture(c: &mut Criterion) {
    let uniform = Uniform::new(0.0f32, 1.0).unwrap();
    let loss = |points: Points, slices: usize| {
        TextureLoss::new(
            PatchPyramid::new(PatchPyramidConfig::default()).unwrap(),
            TextureLossConfig::default()
                .with_points(points)
                .with_slices(Slices::Fixed(slices)),
        )
        .unwrap()
    };
    for (name, backward) in [("swd/texture_fwd", false), ("swd/texture_fwd_bwd", true)] {
        let mut group = c.benchmark_group(name);
        group.sample_size(10);
        let run = |value: swd_loss::Result<Tensor>| {
            let value = value.unwrap();
            if backward {
                black_box(value.backward().unwrap());
            } else {
                black_box(value);
            }
        };
        for res in [64usize, 320] {
            let full = loss(Points::All, 64);
            let target = full
                .target(&seeded_tensor(&[1, 3, res, res], uniform, 4))
                .unwrap();
            let generated =
                Var::from_tensor(&seeded_tensor(&[1, 3, res, res], uniform, 5)).unwrap();
            let proj = full
                .draw_projections(&target, &mut ChaCha8Rng::seed_from_u64(6))
                .unwrap();
            group.throughput(Throughput::Elements((res * res) as u64));
            group.bench_with_input(BenchmarkId::from_parameter(res), &res, |b, _| {
                b.iter(|| run(full.loss_with_projections(generated.as_tensor(), &target, &proj)))
            });
            if res != 320 {
                continue;
            }
            for (points, slices) in [(4096, 128), (8192, 64)] {
                let sampled = loss(Points::Random(points), slices);
                let mut rng = ChaCha8Rng::seed_from_u64(7);
                let id = BenchmarkId::from_parameter(format!("{res}_K{slices}_P{points}"));
                group.bench_function(id, |b| {
                    b.iter(|| run(sampled.loss(generated.as_tensor(), &target, &mut rng)))
                });
            }
        }
        group.finish();
    }
}

criterion_group!(benches, sliced, texture);
criterion_main!(benches);

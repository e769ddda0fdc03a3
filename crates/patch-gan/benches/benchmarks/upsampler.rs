//! The 2D upsampler G_N at the `tiny` preset's last scale (two 54^2 renderings doubled to
//! 108^2, the paper's widths): forward, and forward + backward to its weights. glibc's malloc
//! is tuned first as the `volgen` binary does (`volrender::tune_malloc`), or page faults on
//! every fresh activation would dominate.

use std::time::Duration;

use candle_core::{DType, Device, Module, Tensor};
use candle_nn::{VarBuilder, VarMap};
use criterion::Criterion;
use patch_gan::{Upsampler2d, Upsampler2dConfig};

const SIZE: usize = 54;
const BATCH: usize = 2;

fn bench_upsampler(c: &mut Criterion) {
    volrender::tune_malloc();
    let varmap = VarMap::new();
    let vb = VarBuilder::from_varmap(&varmap, DType::F32, &Device::Cpu);
    let upsampler = Upsampler2d::new(&Upsampler2dConfig::default(), vb).unwrap();
    let images = Tensor::randn(0f32, 1., (BATCH, 3, SIZE, SIZE), &Device::Cpu).unwrap();
    let mut group = c.benchmark_group("gan/upsampler_54_to_108");
    group.sample_size(20).warm_up_time(Duration::from_secs(1));
    group.bench_function("forward", |b| {
        b.iter(|| upsampler.forward(&images).unwrap())
    });
    group.bench_function("forward_backward", |b| {
        b.iter(|| {
            let out = upsampler.forward(&images).unwrap();
            out.sqr().unwrap().mean_all().unwrap().backward().unwrap()
        })
    });
    group.finish();
}

criterion::criterion_group!(benches, bench_upsampler);

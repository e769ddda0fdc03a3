//! Conv3d forward and forward+backward against candle's own matmul, in the same run.
//!
//! Throughput is in floating-point operations (criterion prints them as "elem/s"), so the
//! Gelem/s figures are GFLOP/s: `2 N C_out C_in 27 D H W` per forward, three times that for
//! forward + backward (forward, input gradient, weight gradient).

use std::time::Duration;

use candle_core::{Device, Tensor, Var};
use criterion::{BenchmarkId, Criterion, Throughput};
use patch_gan::{functional, ConvConfig};

const CHANNELS: usize = 32;
const KERNEL: usize = 3;
const SIZES: [usize; 2] = [40, 64];

fn conv_flops(size: usize) -> u64 {
    (2 * CHANNELS * CHANNELS * KERNEL.pow(3) * size.pow(3)) as u64
}

/// Inputs from candle's RNG after a fixed seed, built outside the timed closures.
fn inputs(size: usize) -> (Tensor, Tensor) {
    let dev = Device::Cpu;
    let x = Tensor::randn(0f32, 1., (1, CHANNELS, size, size, size), &dev).unwrap();
    let w = Tensor::randn(
        0f32,
        0.05,
        (CHANNELS, CHANNELS, KERNEL, KERNEL, KERNEL),
        &dev,
    )
    .unwrap();
    (x, w)
}

fn conv3d_forward(c: &mut Criterion) {
    let cfg = ConvConfig::default().with_padding(1);
    let mut group = c.benchmark_group("gan/conv3d_fwd");
    group.sample_size(10).warm_up_time(Duration::from_secs(1));
    for size in SIZES {
        let (x, w) = inputs(size);
        group.throughput(Throughput::Elements(conv_flops(size)));
        group.bench_with_input(BenchmarkId::from_parameter(size), &size, |b, _| {
            b.iter(|| functional::conv3d(&x, &w, cfg).unwrap())
        });
    }
    group.finish();
}

fn conv3d_forward_backward(c: &mut Criterion) {
    let cfg = ConvConfig::default().with_padding(1);
    let mut group = c.benchmark_group("gan/conv3d_fwd_bwd");
    group.sample_size(10).warm_up_time(Duration::from_secs(1));
    for size in SIZES {
        let (x, w) = inputs(size);
        let (x, w) = (Var::from_tensor(&x).unwrap(), Var::from_tensor(&w).unwrap());
        group.throughput(Throughput::Elements(3 * conv_flops(size)));
        group.bench_with_input(BenchmarkId::from_parameter(size), &size, |b, _| {
            b.iter(|| {
                let y = functional::conv3d(x.as_tensor(), w.as_tensor(), cfg).unwrap();
                y.sum_all().unwrap().backward().unwrap()
            })
        });
    }
    group.finish();
}

/// candle's matmul on the conv's own GEMM shape, `(C_out, C_in 27) x (C_in 27, D H W)` (what an
/// im2col conv would cost if building the im2col matrix were free), and on a square 1024^3.
fn candle_matmul(c: &mut Criterion) {
    let dev = Device::Cpu;
    let mut group = c.benchmark_group("gan/candle_matmul");
    group.sample_size(10).warm_up_time(Duration::from_secs(1));
    let patch = CHANNELS * KERNEL.pow(3);
    for size in SIZES {
        let a = Tensor::randn(0f32, 1., (CHANNELS, patch), &dev).unwrap();
        let b = Tensor::randn(0f32, 1., (patch, size.pow(3)), &dev).unwrap();
        group.throughput(Throughput::Elements(conv_flops(size)));
        group.bench_with_input(BenchmarkId::new("conv_shape", size), &size, |bench, _| {
            bench.iter(|| a.matmul(&b).unwrap())
        });
    }
    let n = 1024;
    let a = Tensor::randn(0f32, 1., (n, n), &dev).unwrap();
    let b = Tensor::randn(0f32, 1., (n, n), &dev).unwrap();
    group.throughput(Throughput::Elements((2 * n * n * n) as u64));
    group.bench_with_input(BenchmarkId::new("square", n), &n, |bench, _| {
        bench.iter(|| a.matmul(&b).unwrap())
    });
    group.finish();
}

criterion::criterion_group!(
    benches,
    conv3d_forward,
    conv3d_forward_backward,
    candle_matmul
);

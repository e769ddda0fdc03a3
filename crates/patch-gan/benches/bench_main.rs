//! patch-gan's criterion benchmarks: Conv3d against candle's matmul, and critic steps.

// Setting candle's environment switches (`std::env::set_var`) is `unsafe`; nothing else is.
#![allow(unsafe_code)]

mod benchmarks;

criterion::criterion_main!(
    benchmarks::conv3d::benches,
    benchmarks::critic::benches,
    benchmarks::upsampler::benches
);

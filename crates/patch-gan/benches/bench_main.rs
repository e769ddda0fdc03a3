mod benchmarks;

criterion::criterion_main!(
    benchmarks::conv3d::benches,
    benchmarks::critic::benches,
    benchmarks::upsampler::benches
);

mod benchmarks;

criterion::criterion_main!(benchmarks::conv3d::benches);

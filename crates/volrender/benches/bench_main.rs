//! Criterion benches of the render op: `cargo bench -p volrender`.
mod benchmarks;

criterion::criterion_main!(benchmarks::render::benches);

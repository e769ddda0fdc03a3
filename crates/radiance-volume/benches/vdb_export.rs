//! Export time of OpenVDB files (and EXR slice stacks) for a dense and a 5%-occupied 128^3
//! volume: the VDB writer stores only occupied 8^3 leaves, so its time should follow occupancy.
//!
//! Run: `cargo bench -p radiance-volume --features vdb,exr --bench vdb_export`

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use radiance_volume::{Aabb, GridDims, RadianceVolume};

/// A 128^3 volume whose density is positive inside a ball holding `fraction` of the box (all of
/// it when `fraction >= 1`), with a colour gradient.
fn volume(fraction: f32) -> RadianceVolume {
    // Ball volume 4/3 pi r^3 = fraction * 8 (the box [-1, 1]^3).
    let radius = (fraction * 8.0 * 3.0 / (4.0 * std::f32::consts::PI)).cbrt();
    RadianceVolume::from_fn(GridDims::cube(128), Aabb::CUBE, 4, |p, out| {
        let inside = fraction >= 1.0 || p.length() < radius;
        out[0] = if inside { 1.0 + p.x * p.x } else { 0.0 };
        out[1..4].copy_from_slice(&[0.5 + 0.5 * p.x, 0.5 + 0.5 * p.y, 0.5 + 0.5 * p.z]);
    })
    .expect("a valid volume")
}

fn bench_write_vdb(c: &mut Criterion) {
    let mut group = c.benchmark_group("volume/write_vdb");
    group.sample_size(10);
    for (name, fraction) in [("dense", 1.0), ("occupied5pct", 0.05)] {
        let v = volume(fraction);
        for (codec, half, zlib) in [
            ("f32", false, false),
            ("f16", true, false),
            ("f32_zlib", false, true),
        ] {
            let bytes = v
                .write_vdb()
                .half(half)
                .zlib(zlib)
                .to_writer(std::io::sink())
                .expect("export")
                .bytes;
            group.throughput(Throughput::Bytes(bytes));
            group.bench_function(BenchmarkId::new(format!("{name}-{codec}"), 128), |b| {
                b.iter(|| {
                    v.write_vdb()
                        .half(half)
                        .zlib(zlib)
                        .to_writer(std::io::sink())
                        .expect("export")
                })
            });
        }
    }
    group.finish();
}

fn bench_write_exr(c: &mut Criterion) {
    let mut group = c.benchmark_group("volume/write_exr_slices");
    group.sample_size(10);
    let v = volume(0.05);
    let dir = tempfile::tempdir().expect("a temporary directory");
    group.throughput(Throughput::Elements(v.dims().voxel_count() as u64));
    group.bench_function(BenchmarkId::new("occupied5pct-f32", 128), |b| {
        b.iter(|| {
            v.write_exr_slices()
                .to_dir(dir.path(), "bench")
                .expect("export")
        })
    });
    group.finish();
}

criterion_group!(benches, bench_write_vdb, bench_write_exr);
criterion_main!(benches);

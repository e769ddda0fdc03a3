//! OpenVDB import: a file our writer made, then damaged, read back into a grid. The reader must
//! return a volume of finite values or an error, never panic or allocate without bound.
#![no_main]

use libfuzzer_sys::fuzz_target;
use radiance_volume::{Aabb, GridDims, VoxelGrid};
use volgen_fuzz::{assert_finite, Damage, SmallVolume};

fuzz_target!(|input: (SmallVolume, bool, bool, Damage)| {
    volgen_fuzz::let_caught_panics_unwind();
    let (volume, half, zlib, damage) = input;
    let Some(volume) = volume.build() else {
        return;
    };
    let mut bytes = Vec::new();
    if volume
        .write_vdb()
        .half(half)
        .zlib(zlib)
        .to_writer(&mut bytes)
        .is_err()
    {
        return;
    }
    let bytes = damage.apply(bytes);
    let grid = VoxelGrid::new(Aabb::CUBE, GridDims::cube(8)).unwrap();
    if let Ok(back) =
        radiance_volume::RadianceVolume::read_vdb_bytes(bytes, &grid, "fuzz.vdb".as_ref())
    {
        assert_finite(&back, "vdb");
    }
});

//! EXR slices and their JSON sidecar: files our writer made, then damaged (any slice's bytes,
//! the sidecar's text, or the sidecar replaced), read back. Finite values or an error.
#![no_main]

use libfuzzer_sys::fuzz_target;
use radiance_volume::RadianceVolume;
use volgen_fuzz::{assert_finite, Damage, SmallVolume};

fuzz_target!(|input: (SmallVolume, bool, u8, Damage, Option<String>)| {
    let (volume, half, slice, damage, sidecar) = input;
    let Some(volume) = volume.build() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let Ok(files) = volume.write_exr_slices().half(half).to_dir(dir.path(), "v") else {
        return;
    };
    // The files: slices first, the sidecar last.
    let target = &files[usize::from(slice) % files.len()];
    let bytes = std::fs::read(target).unwrap();
    std::fs::write(target, damage.apply(bytes)).unwrap();
    if let Some(text) = sidecar {
        std::fs::write(dir.path().join("v.json"), text).unwrap();
    }
    if let Ok(back) = RadianceVolume::read_exr_slices(dir.path(), "v") {
        assert_finite(&back, "exr slices");
    }
});

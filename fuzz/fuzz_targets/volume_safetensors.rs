//! Volume safetensors: a file our writer made, then damaged, parsed back. Finite values or an
//! error.
#![no_main]

use libfuzzer_sys::fuzz_target;
use radiance_volume::RadianceVolume;
use volgen_fuzz::{assert_finite, Damage, SmallVolume};

fuzz_target!(|input: (SmallVolume, Damage)| {
    let (volume, damage) = input;
    let Some(volume) = volume.build() else {
        return;
    };
    let bytes = damage.apply(volume.to_safetensors_bytes().unwrap());
    if let Ok(back) = RadianceVolume::from_safetensors_bytes(&bytes, "fuzz.safetensors".as_ref()) {
        assert_finite(&back, "safetensors");
    }
});

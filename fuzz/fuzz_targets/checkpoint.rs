//! Training checkpoints (safetensors with the configuration and progress as JSON metadata):
//! arbitrary bytes, seeded with a real `micro` checkpoint, loaded as `volgen sample` and
//! `--resume` load them (the checkpoint, then the model it describes), then one scene is
//! generated. Errors are fine; panics and unbounded allocations are not.
#![no_main]

use candle_core::Device;
use libfuzzer_sys::fuzz_target;
use rand::SeedableRng;
use singrav::SinGrav;

fuzz_target!(|bytes: &[u8]| {
    let dir = tempfile::tempdir().unwrap();
    let path = singrav::RunDir::new(dir.path()).checkpoint();
    std::fs::write(&path, bytes).unwrap();
    let Ok((model, _state)) = SinGrav::load(&path, &Device::Cpu) else {
        return;
    };
    let mut rng = rand::rngs::StdRng::seed_from_u64(0);
    if let Ok(noise) = model.draw_noise(model.volume_scales(), &mut rng) {
        let _ = model.generate(&noise);
    }
});

//! Writes a model of a preset's shape with untrained weights, marked as fully trained, so that
//! `volgen sample`, `export`, `mesh`, `edit` and `compose` can be measured at that size (peak
//! memory with `/usr/bin/time -v`) without a training
//! run: what they hold follows from the sizes, not from the weights. Untrained generators make
//! thin fog everywhere, so a VDB of the samples has every leaf (as many as any scene can have).
//!
//! Settings change the preset as `volgen train --set` does; the schedule follows the number of
//! 3D scales (its iterations do not matter to a model nobody trains). The `hd` preset's shape
//! (issue 82) from `small`:
//!
//! ```text
//! cargo run --release -p research --example untrained_model -- runs/hd-shape small \
//!     'pyramid.volume_sizes=[16,23,32,45,63,89,126]' \
//!     'pyramid.image_sizes=[32,42,55,72,94,122,160]' \
//!     'pyramid.samples=[48,61,74,88,101,114,128]'
//! ```

use std::path::PathBuf;

use candle_core::Device;
use singrav::checkpoint::{Checkpoint, TrainState};
use singrav::noise::step_rng;
use singrav::{RunDir, SinGrav, TrainConfig};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let usage = "usage: untrained_model OUT PRESET [PATH=VALUE ...]";
    let out = PathBuf::from(args.next().ok_or(usage)?);
    let mut config = TrainConfig::preset(&args.next().ok_or(usage)?)?;
    for setting in args {
        let (path, value) = setting.split_once('=').ok_or(usage)?;
        config = config.with_setting(path, value)?;
    }
    let volumes = config.pyramid.volume_sizes.len();
    let last = *config
        .schedule
        .scales
        .last()
        .ok_or("the preset has no schedule")?;
    config.schedule.scales.resize(volumes + 1, last);
    if let Some(views) = &mut config.schedule.scale_views {
        let last = *views.last().ok_or("the preset has empty scale views")?;
        views.resize(volumes + 1, last);
    }
    config.validate()?;

    let mut rng = step_rng(0, 0, 0);
    let mut model = SinGrav::new(&config, &Device::Cpu, &mut rng)?;
    // The amplitudes training would give the finer scales are about this (tiny's runs).
    let amps = vec![0.1; volumes];
    for &amp in &amps {
        model.push_generator(amp, &mut rng)?;
    }
    model.push_upsampler(&mut rng)?;
    let state = TrainState {
        scale: config.scales() + 1,
        iteration: 0,
        noise_amps: amps,
        upsampler: true,
        depth_norm: 1.0,
        optimizer_steps: (0, 0),
        scale_seconds: Vec::new(),
        current_seconds: 0.0,
        scale_peak_mib: Vec::new(),
    };
    std::fs::create_dir_all(&out)?;
    Checkpoint {
        config: config.clone(),
        state,
        tensors: model.tensors(),
    }
    .save(&RunDir::new(&out).checkpoint())?;
    println!(
        "{}: untrained model, volumes {:?}, renderings {:?}, final pictures {}^2",
        out.display(),
        config.pyramid.volume_sizes,
        config.pyramid.image_sizes,
        config.final_image_size()
    );
    Ok(())
}

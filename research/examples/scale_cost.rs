//! Measures what one generator step costs at each 3D scale of a preset: a forward and backward
//! pass of G_n on its volume plus a rendering of the preset's views per step, with the time and
//! the process's peak memory. Used for docs/training.md ("what the paper preset needs").
//!
//! `cargo run --release -p research --example scale_cost -- paper [max_scale]`

use std::time::Instant;

use candle_core::{DType, Device, Tensor};
use singrav::noise::{gaussian_volume, step_rng};
use singrav::render::ViewRenderer;
use singrav::sample::showcase_cameras;
use singrav::{SinGrav, TrainConfig};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let preset = args.next().unwrap_or_else(|| "paper".into());
    let config = TrainConfig::preset(&preset)?;
    let max_scale: usize = match args.next() {
        Some(s) => s.parse()?,
        None => config.pyramid.volume_sizes.len(),
    };
    let device = Device::Cpu;
    let mut rng = step_rng(0, 0, 0);
    let mut model = SinGrav::new(&config, &device, &mut rng)?;
    println!("preset {preset}: one generator step (G_n forward + backward, render {} views forward + backward)", config.schedule.views_per_step);
    println!("| scale | volume | image | G_n fwd+bwd (s) | render fwd+bwd (s) | peak RSS (MiB) |");
    println!("|---|---|---|---|---|---|");
    for n in 1..=max_scale.min(config.pyramid.volume_sizes.len()) {
        model.push_generator(0.1, &mut rng)?;
        let size = config.pyramid.volume_sizes[n - 1];
        let started = Instant::now();
        let raw = if n == 1 {
            model.coarsest(model.z_star())?
        } else {
            let prev = Tensor::zeros((1, 4, size, size, size), DType::F32, &device)?;
            let z = gaussian_volume(&mut rng, 4, size, 0.1, &device)?;
            model.refine(n, &z, &prev)?
        };
        raw.sqr()?.mean_all()?.backward()?;
        let generator = started.elapsed().as_secs_f64();
        let image = config.pyramid.image_sizes[n - 1];
        let renderer = ViewRenderer::new(&config, config.pyramid.samples[n - 1], 5.0, true);
        let cameras = showcase_cameras(config.schedule.views_per_step, image)?;
        let refs: Vec<_> = cameras.iter().collect();
        // A leaf of its own, so the backward below stops at the volume.
        let volume = candle_core::Var::from_tensor(&raw.detach())?;
        let started = Instant::now();
        let (rgb, _) = renderer.render(volume.as_tensor(), &refs)?;
        rgb.mean_all()?.backward()?;
        let render = started.elapsed().as_secs_f64();
        println!(
            "| {n} | {size}^3 | {image}^2 | {generator:.2} | {render:.2} | {:.0} |",
            singrav::train::peak_memory_mib().unwrap_or(f64::NAN)
        );
    }
    Ok(())
}

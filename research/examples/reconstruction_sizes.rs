//! How close a trained run's reconstruction V* comes to the dataset's views at each size it can
//! be rendered at: the model's own renderer, one ray per pixel, from 8 evenly spaced views at
//! the last 3D scale's size, at twice it directly and through the upsampler, and at the
//! dataset's own size; colour PSNR and depth RMSE (world units). Used for docs/training.md
//! ("Fitting V* to the views after training"), where it showed a V* fitted after training to be
//! far closer at the views' size and further at the last 3D scale's.
//!
//! ```text
//! cargo run --release -p research --example reconstruction_sizes -- DATASET RUN...
//! ```

use candle_core::{Device, Tensor};
use rgbd_dataset::Dataset;
use scene_metrics::{depth_rmse, mean_psnr};
use singrav::render::ViewRenderer;
use singrav::SinGrav;

/// Views compared, evenly spaced over the dataset's frames.
const VIEWS: usize = 8;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [dataset, runs @ ..] = args.as_slice() else {
        return Err("usage: reconstruction_sizes DATASET RUN...".into());
    };
    if runs.is_empty() {
        return Err("usage: reconstruction_sizes DATASET RUN...".into());
    }
    let device = Device::Cpu;
    println!("| run | rendered at | PSNR (dB) | depth RMSE |");
    println!("|---|---|---|---|");
    for run in runs {
        let (model, _) = SinGrav::load(run.as_ref(), &device)?;
        let scene = Dataset::load(dataset.as_ref(), model.config().rendering.background)?;
        let data = match &model.config().run.bounds {
            Some(bounds) => scene.in_model_cube(bounds)?,
            None => scene,
        };
        let frames: Vec<usize> = (0..VIEWS).map(|i| i * data.len() / VIEWS).collect();
        let chosen = data.subset(&frames)?;
        let v_star = model.reconstruct()?;
        let samples = *model.config().pyramid.samples.last().ok_or("no 3D scale")?;
        let renderer = ViewRenderer::new(model.config(), samples, 1.0, true);
        let coarse = model.render_size();
        for size in [coarse, 2 * coarse, data.width()] {
            let level = chosen.level(size, size, &device)?;
            let cameras: Vec<_> = level.cameras.iter().collect();
            let maps = renderer.render_maps(&v_star, &cameras)?;
            let psnr = mean_psnr(&maps.rgb, &level.images)?;
            let depth = depth_rmse(&maps.depth, &level.depths)?;
            println!("| {run} | {size}^2 | {psnr:.2} | {depth:.4} |");
            if size == coarse && model.has_upsampler() {
                let up: Tensor = model.upsample_images(&maps.rgb)?.clamp(0f32, 1f32)?;
                let real = chosen.level(2 * size, 2 * size, &device)?.images;
                let psnr = mean_psnr(&up, &real)?;
                println!("| {run} | {size}^2 doubled by the upsampler | {psnr:.2} | |");
            }
        }
    }
    Ok(())
}

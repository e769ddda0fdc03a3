//! `volgen fit` against the plain direct fit a user would write first, side by side in one run.
//!
//! The plain fit is the recipe of issue 19's table: a raw `(4, S, S, S)` candle `Var`, the
//! training activation (scale 25, shift -4), volrender's `render` with 2S uniform samples, white
//! background and depth, candle-nn's AdamW at lr 0.05, one whole view per step, loss
//! `10 mse(colour) + 1.2 mse(depth)`, 600 steps. `volume_fit` then gets half the plain fit's
//! measured wall time (`FitBudget::Seconds`). Both are scored by the same PSNR over the
//! training views and over held-out views (every 10th), rendered at the dataset's resolution.
//!
//! ```text
//! cargo run --release -p research --example fit_vs_plain -- [DATASET] [SIZES...]
//! ```
//!
//! Without a dataset it renders the demo's (stones, 100 views at 128^2) into a temporary
//! directory. Sizes default to 28 and 64.

use std::time::Instant;

use candle_core::{DType, Device, Var};
use candle_nn::{AdamW, Optimizer, ParamsAdamW};
use radiance_volume::{Aabb, RadianceVolume};
use rand::seq::SliceRandom;
use rand::SeedableRng;
use rgbd_dataset::{write_dataset, Dataset, DatasetSpec};
use singrav::TrainConfig;
use volrender::{render, Rays, RenderConfig, Sampler};
use volume_fit::{fit_volume, view_psnr, FitBudget, FitConfig};

type Result<T> = std::result::Result<T, Box<dyn std::error::Error>>;

/// Steps of the plain fit, as in the issue.
const PLAIN_STEPS: usize = 600;

fn main() -> Result<()> {
    let mut args = std::env::args().skip(1).peekable();
    let temp = tempfile::tempdir()?;
    let dataset_dir = match args.peek() {
        Some(first) if first.parse::<usize>().is_err() => args.next().unwrap().into(),
        _ => {
            let spec = DatasetSpec {
                views: 100,
                resolution: 128,
                ..DatasetSpec::default()
            };
            write_dataset(
                &rgbd_dataset::scenes::StandingStones::new(0),
                temp.path(),
                &spec,
            )?;
            temp.path().to_path_buf()
        }
    };
    let sizes: Vec<usize> = args
        .map(|a| a.parse())
        .collect::<std::result::Result<_, _>>()?;
    let sizes = if sizes.is_empty() {
        vec![28, 64]
    } else {
        sizes
    };
    let training = TrainConfig::preset("tiny")?;
    let data = Dataset::load(&dataset_dir, training.rendering.background)?;
    let (train_views, held_out) = data.holdout_split(10)?;
    println!(
        "{} training and {} held-out views at {}x{} ({})",
        train_views.len(),
        held_out.len(),
        data.width(),
        data.height(),
        dataset_dir.display()
    );
    println!("| grid | plain: time | plain: PSNR train / held-out | volgen fit: time | volgen fit: PSNR train / held-out | volgen steps |");
    println!("|---|---|---|---|---|---|");
    for size in sizes {
        let config = FitConfig {
            size,
            ..FitConfig::default()
        };
        let started = Instant::now();
        let plain = plain_fit(&data, &train_views, size, &training)?;
        let plain_seconds = started.elapsed().as_secs_f64();
        let fitted = fit_volume(
            &data,
            &train_views,
            &FitConfig {
                budget: FitBudget::Seconds(plain_seconds / 2.0),
                ..config.clone()
            },
            &mut |_| {},
        )?;
        let score = |v: &RadianceVolume| -> Result<(f64, f64)> {
            let mean = |p: Vec<f64>| p.iter().sum::<f64>() / p.len() as f64;
            Ok((
                mean(view_psnr(v, &data, &train_views, &config)?),
                mean(view_psnr(v, &data, &held_out, &config)?),
            ))
        };
        let (plain_train, plain_held) = score(&plain)?;
        let (fit_train, fit_held) = score(&fitted.volume)?;
        println!(
            "| {size}^3 | {plain_seconds:.1} s | {plain_train:.2} / {plain_held:.2} dB | {:.1} s | {fit_train:.2} / {fit_held:.2} dB | {} |",
            fitted.seconds, fitted.steps
        );
    }
    Ok(())
}

/// The issue's plain fit; returns the physical volume.
fn plain_fit(
    data: &Dataset,
    views: &[usize],
    size: usize,
    training: &TrainConfig,
) -> Result<RadianceVolume> {
    let device = Device::Cpu;
    let level = data
        .subset(views)?
        .level(data.width(), data.height(), &device)?;
    let raw = Var::zeros((4, size, size, size), DType::F32, &device)?;
    let mut opt = AdamW::new(
        vec![raw.clone()],
        ParamsAdamW {
            lr: 0.05,
            ..ParamsAdamW::default()
        },
    )?;
    let activation = training.activation();
    let render_config = RenderConfig::default()
        .with_sampler(Sampler::Uniform { samples: 2 * size })
        .with_background(training.rendering.background)
        .with_depth(true);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0);
    let mut order: Vec<usize> = (0..views.len()).collect();
    for step in 0..PLAIN_STEPS {
        if step % order.len() == 0 {
            order.shuffle(&mut rng);
        }
        let v = order[step % order.len()];
        let camera = &level.cameras[v];
        let out = render(
            &activation.apply(raw.as_tensor())?,
            &Rays::from_camera(camera),
            &render_config,
        )?;
        let (h, w) = (camera.height, camera.width);
        let rgb = out.rgb.reshape((h, w, 3))?.permute((2, 0, 1))?;
        let depth = out.depth.ok_or("depth was asked for")?.reshape((1, h, w))?;
        let colour_loss = (rgb - level.images.get(v)?)?.sqr()?.mean_all()?;
        let depth_loss = (depth - level.depths.get(v)?)?.sqr()?.mean_all()?;
        let loss = ((colour_loss * 10.0)? + (depth_loss * 1.2)?)?;
        opt.backward_step(&loss)?;
    }
    Ok(RadianceVolume::new(
        activation.apply(&raw.as_tensor().detach())?,
        Aabb::CUBE,
    )?)
}

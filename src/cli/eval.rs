//! `volgen eval MODEL --dataset DIR [--scenes N] [--views V] [--seed S] [--inception FILE]`:
//! the paper's metrics of a trained model. Generates scenes, renders each from cameras of the
//! training dataset, and compares the renderings with the dataset's images from the same
//! cameras: Diversity-MV always, SIFID-MV when InceptionV3 weights are given.

use std::path::{Path, PathBuf};

use super::model_io::load_model;
use super::train::{device, load_dataset};
use anyhow::{ensure, Context, Result};
use candle_core::Tensor;
use rand::SeedableRng;
use serde::Serialize;
use singrav::checkpoint::checkpoint_path;
use singrav::dataset::DepthKind;
use singrav::metrics::{diversity_mv, sifid_mv, InceptionBlock1};

/// Arguments of `volgen eval`.
#[derive(Debug, clap::Args)]
#[command(after_help = "The paper evaluates 50 scenes from 40 views each \
    (--scenes 50 --views 40); the defaults are small enough to run in seconds on the tiny \
    preset. docs/metrics.md explains the numbers and how to convert InceptionV3's weights.")]
pub struct EvalArgs {
    /// A trained model: a run directory or its checkpoint.safetensors.
    model: PathBuf,
    /// The dataset the model was trained on (a transforms.json or its directory): its images
    /// are the real views. Required because a run does not record where its dataset was.
    #[arg(long, value_name = "DIR")]
    dataset: PathBuf,
    /// How the dataset's depth maps measure depth, when its transforms.json does not say (as
    /// `volgen train --depth-kind`).
    #[arg(long, value_name = "KIND")]
    depth_kind: Option<DepthKind>,
    /// Scenes to generate (at least 2; the paper: 50).
    #[arg(long, default_value_t = 8)]
    scenes: usize,
    /// Dataset views to compare, evenly spaced over its frames (the paper: 40).
    #[arg(long, default_value_t = 4)]
    views: usize,
    /// Seed of the noise; the same seed gives the scenes `volgen sample --seed` gives.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// InceptionV3 weights (torchvision's names, safetensors) for SIFID-MV; without them only
    /// Diversity-MV is computed.
    #[arg(long, value_name = "FILE")]
    inception: Option<PathBuf>,
    /// Where to write the numbers as JSON (default: eval.json in the run directory).
    #[arg(long, value_name = "FILE")]
    out: Option<PathBuf>,
}

/// What `eval.json` holds.
#[derive(Debug, Serialize)]
struct Evaluation {
    model: PathBuf,
    dataset: PathBuf,
    scenes: usize,
    seed: u64,
    /// The dataset frames (their `file_path`) the scenes were seen from.
    views: Vec<String>,
    /// Edge of the compared images in pixels.
    image_size: usize,
    /// Higher is more varied; 0 when every scene is the same.
    diversity_mv: f64,
    /// Lower is closer to the real views' statistics; null without InceptionV3 weights.
    sifid_mv: Option<f64>,
    inception: Option<PathBuf>,
}

/// Evaluates as the arguments say.
pub fn run(args: &EvalArgs) -> Result<()> {
    ensure!(
        args.scenes >= 2,
        "--scenes must be at least 2: Diversity-MV is a spread over scenes"
    );
    ensure!(args.views >= 1, "--views must be at least 1");
    let device = device()?;
    // Weights first: a wrong path should fail before minutes of generation.
    let block = args
        .inception
        .as_ref()
        .map(|path| InceptionBlock1::from_safetensors(path, &device))
        .transpose()?;
    let model = load_model(&args.model)?;
    let dataset = load_dataset(&args.dataset, model.config(), args.depth_kind)?;
    // The model renders in its own cube: a run trained with --bounds sees the views there.
    let dataset = match &model.config().bounds {
        Some(bounds) => dataset.in_model_cube(bounds)?,
        None => dataset,
    };
    ensure!(
        args.views <= dataset.len(),
        "--views {} is more than the {} frames of {}",
        args.views,
        dataset.len(),
        args.dataset.display()
    );
    let frames: Vec<usize> = (0..args.views)
        .map(|i| i * dataset.len() / args.views)
        .collect();
    let chosen = dataset.subset(&frames)?;
    let size = model.render_size();
    let cameras = chosen.level(size, size, &device)?.cameras;

    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(args.seed);
    let mut generated: Vec<Tensor> = Vec::with_capacity(args.scenes);
    for i in 0..args.scenes {
        generated.push(model.sample(&mut rng, &cameras)?.views);
        eprintln!("scene {}/{} rendered", i + 1, args.scenes);
    }
    // The upsampler, when trained, doubles the renderings: compare at the size they came out.
    let image_size = generated[0].dim(3)?;
    let real = chosen.level(image_size, image_size, &device)?.images;

    let diversity = diversity_mv(&generated, &real)?;
    let sifid = block
        .as_ref()
        .map(|b| sifid_mv(&generated, &real, b))
        .transpose()?;
    println!(
        "{} scenes x {} views at {image_size}x{image_size} (seed {})",
        args.scenes, args.views, args.seed
    );
    println!("Diversity-MV: {diversity:.4}  (higher = more varied scenes)");
    match sifid {
        Some(s) => println!("SIFID-MV:     {s:.4}  (lower = closer to the real views)"),
        None => println!(
            "SIFID-MV:     not computed: it needs InceptionV3 weights (--inception \
             FILE.safetensors); docs/metrics.md shows how to convert torchvision's"
        ),
    }

    let evaluation = Evaluation {
        model: args.model.clone(),
        dataset: args.dataset.clone(),
        scenes: args.scenes,
        seed: args.seed,
        views: chosen.frame_names().to_vec(),
        image_size,
        diversity_mv: diversity,
        sifid_mv: sifid,
        inception: args.inception.clone(),
    };
    let out = args
        .out
        .clone()
        .unwrap_or_else(|| run_dir(&args.model).join("eval.json"));
    radiance_volume::io::write_bytes_atomic(
        &out,
        format!("{}\n", serde_json::to_string_pretty(&evaluation)?).as_bytes(),
    )
    .with_context(|| format!("writing {}", out.display()))?;
    println!("wrote {}", out.display());
    Ok(())
}

/// The run directory of `model` (the directory itself, or the one holding the checkpoint).
fn run_dir(model: &Path) -> PathBuf {
    checkpoint_path(model)
        .parent()
        .map(Path::to_path_buf)
        .unwrap_or_default()
}

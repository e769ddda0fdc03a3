//! `volgen sample MODEL --count N --seed S --out DIR [--reconstruction]`: generate new scenes
//! from a trained model as radiance volumes (safetensors, plus VDB / EXR slices on request) with
//! PNG views; with `--reconstruction`, also the fixed-noise reconstruction V*.

use std::path::{Path, PathBuf};

use anyhow::Result;
use rand::SeedableRng;
use singrav::sample::{showcase_cameras, Sample};
use singrav::SinGrav;

use super::model_io::{load_model, write_scene, Outputs};

/// Arguments of `volgen sample`.
#[derive(Debug, clap::Args)]
pub struct SampleArgs {
    /// A trained model: a run directory or its checkpoint.safetensors.
    model: PathBuf,
    /// How many scenes to generate.
    #[arg(long, default_value_t = 4)]
    count: usize,
    /// Seed of the noise; the same seed gives the same scenes.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Output directory.
    #[arg(long, value_name = "DIR")]
    out: PathBuf,
    #[command(flatten)]
    outputs: Outputs,
    /// Views rendered per scene.
    #[arg(long, default_value_t = 3)]
    views: usize,
    /// Also write the fixed-noise reconstruction V* (the scene training fits to the dataset) as
    /// `reconstruction.*`, in the same formats (`--count 0` writes it alone).
    #[arg(long)]
    reconstruction: bool,
}

/// Generates and writes the scenes.
pub fn run(args: &SampleArgs) -> Result<()> {
    let model = load_model(&args.model)?;
    let cameras = showcase_cameras(args.views, model.render_size())?;
    if args.reconstruction {
        let v_star = model.reconstruction_sample(&cameras)?;
        let files = write_scene(
            &args.out,
            "reconstruction",
            &v_star.volume,
            &v_star.views,
            args.outputs,
        )?;
        println!(
            "reconstruction V*: generated in {:.3} s -> {}",
            v_star.generation_seconds,
            files.display()
        );
    }
    sample_to_dir(
        &model,
        &cameras,
        args.count,
        args.seed,
        &args.out,
        args.outputs,
    )?;
    Ok(())
}

/// Generates `count` scenes seen from `cameras` into `dir` (`scene_i.safetensors`,
/// `scene_i.png`, and VDB / EXR when asked), printing each scene's generation time.
pub fn sample_to_dir(
    model: &SinGrav,
    cameras: &[volrender::Camera],
    count: usize,
    seed: u64,
    dir: &Path,
    outputs: Outputs,
) -> Result<Vec<Sample>> {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let mut samples = Vec::with_capacity(count);
    for i in 0..count {
        let sample = model.sample(&mut rng, cameras)?;
        let files = write_scene(
            dir,
            &format!("scene_{i}"),
            &sample.volume,
            &sample.views,
            outputs,
        )?;
        println!(
            "scene {i}: generated in {:.3} s -> {}",
            sample.generation_seconds,
            files.display()
        );
        samples.push(sample);
    }
    Ok(samples)
}

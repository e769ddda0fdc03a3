//! `volgen sample MODEL --count N --seed S --out DIR [--reconstruction] [--turntable F]`:
//! generate new scenes from a trained model as radiance volumes (safetensors, plus VDB / EXR
//! slices on request) with PNG views; with `--reconstruction`, also the fixed-noise
//! reconstruction V*; with `--turntable F`, an animated GIF per scene, a camera orbit of F frames;
//! with `--vary-from N`, scenes that keep V*'s layout below 3D scale N and vary above it.

use std::path::{Path, PathBuf};

use anyhow::{ensure, Context, Result};
use rand::SeedableRng;
use singrav::sample::Sample;
use singrav::SinGrav;
use volrender::Camera;

use super::extent::ExtentArgs;
use super::model_io::{load_model, write_scene, Outputs};

/// Arguments of `volgen sample`.
#[derive(Debug, clap::Args)]
pub struct SampleArgs {
    /// A trained model: a run directory or its checkpoint.
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
    #[command(flatten)]
    extent: ExtentArgs,
    /// Views rendered per scene.
    #[arg(long, default_value_t = 3)]
    views: usize,
    /// Also write the fixed-noise reconstruction V* (the scene training fits to the dataset) as
    /// `reconstruction.*`, in the same formats (`--count 0` writes it alone).
    #[arg(long)]
    reconstruction: bool,
    /// The coarsest 3D scale whose noise varies: scales below it take the reconstruction's
    /// noise, so every scene keeps V*'s layout and only finer structure varies (1: everything
    /// varies). The same seed gives the same finer noise whatever N.
    #[arg(long, value_name = "N", default_value_t = 1)]
    vary_from: usize,
    /// Also write each scene as an animated GIF (`scene_i.gif`): a full camera orbit at the
    /// showcase views' elevation, in this many frames.
    #[arg(long, value_name = "FRAMES")]
    turntable: Option<usize>,
}

/// How long a turntable frame is shown: 36 frames make a 2.9 s orbit.
const TURNTABLE_FRAME_MS: u32 = 80;

/// Generates and writes the scenes.
pub fn run(args: &SampleArgs) -> Result<()> {
    ensure!(
        args.turntable != Some(0),
        "--turntable: expected at least 1 frame, got 0"
    );
    let mut model = load_model(&args.model)?;
    args.extent.apply(&mut model)?;
    // Before anything is written.
    ensure!(
        !args.reconstruction || args.extent.is_learned_size(),
        "--reconstruction: the reconstruction V* has the learned scene's size; leave out \
         --extent or --reconstruction"
    );
    model
        .check_vary_from(args.vary_from)
        .context("--vary-from")?;
    let views = Views::new(&model, args.views, args.turntable)?;
    if args.reconstruction {
        let mut v_star = model.reconstruction_sample(&views.cameras)?;
        let files = write_sample(
            &model,
            &args.out,
            "reconstruction",
            &mut v_star,
            &views,
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
        &views,
        Draws {
            count: args.count,
            seed: args.seed,
            vary_from: args.vary_from,
        },
        &args.out,
        args.outputs,
    )?;
    Ok(())
}

/// The cameras every scene is rendered from: the views shown in its PNG, then the turntable's
/// orbit (one render call for both).
pub struct Views {
    cameras: Vec<Camera>,
    shown: usize,
}

impl Views {
    /// `shown` cameras for the PNG (as given) and, with `turntable`, that many orbit frames.
    pub fn with_cameras(
        model: &SinGrav,
        shown: Vec<Camera>,
        turntable: Option<usize>,
    ) -> Result<Self> {
        let count = shown.len();
        let mut cameras = shown;
        if let Some(frames) = turntable {
            cameras.extend(model.showcase_cameras(frames)?);
        }
        Ok(Self {
            cameras,
            shown: count,
        })
    }

    /// `shown` showcase cameras and, with `turntable`, that many orbit frames.
    fn new(model: &SinGrav, shown: usize, turntable: Option<usize>) -> Result<Self> {
        Self::with_cameras(model, model.showcase_cameras(shown)?, turntable)
    }
}

/// Which scenes [`sample_to_dir`] generates: `count` of them from `seed`'s noise, varying from
/// 3D scale `vary_from` on.
#[derive(Debug, Clone, Copy)]
pub struct Draws {
    pub count: usize,
    pub seed: u64,
    pub vary_from: usize,
}

/// Generates the scenes of `draws` seen from `views` into `dir` (`scene_i.safetensors`,
/// `scene_i.png`, `scene_i.gif` with a turntable, and VDB / EXR when asked), printing each
/// scene's generation time. The samples returned hold the shown views only.
pub fn sample_to_dir(
    model: &SinGrav,
    views: &Views,
    draws: Draws,
    dir: &Path,
    outputs: Outputs,
) -> Result<Vec<Sample>> {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(draws.seed);
    let mut samples = Vec::with_capacity(draws.count);
    for i in 0..draws.count {
        let mut sample = model.sample_varying_from(&mut rng, &views.cameras, draws.vary_from)?;
        let files = write_sample(
            model,
            dir,
            &format!("scene_{i}"),
            &mut sample,
            views,
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

/// Writes a scene rendered from `views.cameras`: the shown views as its PNG (they stay in
/// `sample.views`), the orbit's frames, if any, as `{stem}.gif`.
fn write_sample(
    model: &SinGrav,
    dir: &Path,
    stem: &str,
    sample: &mut Sample,
    views: &Views,
    outputs: Outputs,
) -> Result<PathBuf> {
    let frames = (views.shown..views.cameras.len())
        .map(|v| sample.views.get(v))
        .collect::<candle_core::Result<Vec<_>>>()?;
    sample.views = sample.views.narrow(0, 0, views.shown)?;
    // At factor 1 this activates the raw volume again (as `sample.volume` was made): a
    // millisecond, against one path for every factor.
    let volume = outputs.volume(model, &sample.raw)?;
    let files = write_scene(dir, stem, &volume, &sample.views, outputs)?;
    if !frames.is_empty() {
        singrav::picture::write_gif(
            &dir.join(format!("{stem}.gif")),
            &frames,
            TURNTABLE_FRAME_MS,
        )?;
    }
    Ok(files)
}

//! `volgen animate MODEL --frames N --seed S --out DIR [--gif]`: the paper's animation, a
//! smoothed random walk on the noise of the finer scales, written frame by frame as physical
//! volumes (`frame_0000.safetensors`, VDB / EXR on request) and a PNG from one fixed camera, and
//! with `--gif` as one animated GIF of those PNG views.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result};
use rand::SeedableRng;
use singrav::applications::WalkConfig;

use super::extent::ExtentArgs;
use super::model_io::{load_model, write_scene, Outputs};

/// Arguments of `volgen animate`.
#[derive(Debug, clap::Args)]
pub struct AnimateArgs {
    /// A trained model: a run directory or its checkpoint.
    model: PathBuf,
    /// How many frames to write.
    #[arg(long, default_value_t = 24)]
    frames: usize,
    /// Seed of the noise; the same seed gives the same animation.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Output directory.
    #[arg(long, value_name = "DIR")]
    out: PathBuf,
    /// Pull of every frame towards the first frame's noise, in [0, 1] (the paper's alpha).
    #[arg(long, default_value_t = WalkConfig::default().anchor)]
    anchor: f64,
    /// Momentum of the walk, in [0, 1] (the paper's xi): higher is smoother.
    #[arg(long, default_value_t = WalkConfig::default().momentum)]
    momentum: f64,
    /// The coarsest 3D scale whose noise moves (coarser scales keep the layout); the paper
    /// moves scales from 3 on.
    #[arg(long, value_name = "N", default_value_t = WalkConfig::default().first_moving_scale)]
    first_moving_scale: usize,
    /// Scales below N take the reconstruction's noise in every frame: V*'s layout, animated
    /// above it (1: the first frame is a random scene).
    #[arg(long, value_name = "N", default_value_t = WalkConfig::default().vary_from)]
    vary_from: usize,
    #[command(flatten)]
    outputs: Outputs,
    #[command(flatten)]
    extent: ExtentArgs,
    /// Also write the frames' views as one looping animated GIF, `animation.gif`.
    #[arg(long)]
    gif: bool,
}

/// How long an animation frame is shown (12.5 frames per second).
const ANIMATION_FRAME_MS: u32 = 80;

/// Generates and writes the frames, printing each frame's generation time.
pub fn run(args: &AnimateArgs) -> Result<()> {
    anyhow::ensure!(
        args.frames > 0,
        "--frames: expected at least 1 frame, got 0"
    );
    let mut model = load_model(&args.model)?;
    args.extent.apply(&mut model)?;
    let walk = WalkConfig {
        anchor: args.anchor,
        momentum: args.momentum,
        first_moving_scale: args.first_moving_scale,
        vary_from: args.vary_from,
    };
    let camera = model.showcase_cameras(1)?;
    let rng = rand_chacha::ChaCha8Rng::seed_from_u64(args.seed);
    let mut animation = model
        .animation(walk, rng)
        .context("setting up the animation")?;
    let mut gif_frames = Vec::new();
    for t in 0..args.frames {
        let started = Instant::now();
        let raw = animation.next_frame()?;
        let seconds = started.elapsed().as_secs_f64();
        let volume = args.outputs.volume(&model, &raw)?;
        let views = model.render_raw(&raw, &camera)?;
        let files = write_scene(
            &args.out,
            &format!("frame_{t:04}"),
            &volume,
            &views,
            args.outputs,
        )?;
        println!(
            "frame {t}: generated in {seconds:.3} s -> {}",
            files.display()
        );
        if args.gif {
            gif_frames.push(views.get(0)?);
        }
    }
    if args.gif {
        let path = args.out.join("animation.gif");
        singrav::picture::write_gif(&path, &gif_frames, ANIMATION_FRAME_MS)?;
        println!("animation -> {}", path.display());
    }
    Ok(())
}

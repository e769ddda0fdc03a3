//! `volgen sample MODEL --count N --seed S --out DIR`: generate new scenes from a trained model
//! as radiance volumes (safetensors, plus VDB / EXR slices on request) with PNG views.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use rand::SeedableRng;
use singrav::sample::{showcase_cameras, Sample};
use singrav::SinGrav;

use super::export::{write_exr_slices, write_vdb, Encoding};

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
    /// Also write each scene as OpenVDB (density and color grids).
    #[arg(long)]
    vdb: bool,
    /// Also write each scene as a stack of EXR slices.
    #[arg(long)]
    exr_slices: bool,
    /// Views rendered per scene.
    #[arg(long, default_value_t = 3)]
    views: usize,
}

/// What to write for each scene.
#[derive(Debug, Clone, Copy)]
pub struct Outputs {
    /// Write `scene_i.vdb`.
    pub vdb: bool,
    /// Write `scene_i_exr/`.
    pub exr_slices: bool,
}

/// Generates and writes the scenes.
pub fn run(args: &SampleArgs) -> Result<()> {
    let (model, state) = SinGrav::load(&args.model, &super::train::device()?)?;
    if !state.finished(model.config()) {
        eprintln!(
            "note: {} is not fully trained (stopped at scale {}); sampling from its trained scales",
            args.model.display(),
            state.scale
        );
    }
    let cameras = showcase_cameras(args.views, model.render_size())?;
    let outputs = Outputs {
        vdb: args.vdb,
        exr_slices: args.exr_slices,
    };
    sample_to_dir(&model, &cameras, args.count, args.seed, &args.out, outputs)?;
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
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let mut samples = Vec::with_capacity(count);
    for i in 0..count {
        let sample = model.sample(&mut rng, cameras)?;
        let stem = format!("scene_{i}");
        sample
            .volume
            .save_safetensors(dir.join(format!("{stem}.safetensors")))?;
        let views = (0..cameras.len())
            .map(|v| sample.views.get(v))
            .collect::<candle_core::Result<Vec<_>>>()?;
        singrav::picture::write_grid(&dir.join(format!("{stem}.png")), &[views])?;
        if outputs.vdb {
            write_vdb(
                &sample.volume,
                &dir.join(format!("{stem}.vdb")),
                &Encoding::default(),
            )?;
        }
        if outputs.exr_slices {
            write_exr_slices(
                &sample.volume,
                &dir.join(format!("{stem}_exr")),
                &stem,
                &Encoding::default(),
            )?;
        }
        println!(
            "scene {i}: generated in {:.3} s -> {}",
            sample.generation_seconds,
            dir.join(format!("{stem}.*")).display()
        );
        samples.push(sample);
    }
    Ok(samples)
}

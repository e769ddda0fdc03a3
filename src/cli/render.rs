//! `volgen render VOLUME --cameras transforms.json --width W --height H --out DIR`: render a
//! volume from every camera of a NeRF `transforms.json`, as float EXRs and PNG previews.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use radiance_volume::RadianceVolume;
use volrender::{load_transforms, render_image, RenderConfig, Sampler};

/// Arguments of `volgen render`.
#[derive(Debug, clap::Args)]
pub struct RenderArgs {
    /// A volume in volgen's safetensors format (physical: sigma >= 0, colour in [0, 1]).
    volume: PathBuf,
    /// A NeRF-style transforms.json with the cameras to render from.
    #[arg(long, value_name = "FILE")]
    cameras: PathBuf,
    /// Image width in pixels.
    #[arg(long)]
    width: usize,
    /// Image height in pixels.
    #[arg(long)]
    height: usize,
    /// Uniform midpoint samples per ray (default 128).
    #[arg(long, value_name = "M", conflicts_with = "per_voxel")]
    samples: Option<usize>,
    /// Voxel-aware sampling: K samples per voxel crossed.
    #[arg(long, value_name = "K")]
    per_voxel: Option<usize>,
    /// Early ray termination threshold on transmittance (0 = exact).
    #[arg(long, value_name = "E", default_value_t = 0.0)]
    epsilon: f32,
    /// Do not skip empty space (results are the same; only slower).
    #[arg(long)]
    no_skip: bool,
    /// Colour seen where rays leave the volume, each in [0, 1] (default black): a SinGRAV
    /// run renders on its configuration's `rendering.background` (white for the presets).
    #[arg(long, value_name = "R,G,B", value_parser = background)]
    background: Option<[f32; 3]>,
    /// Output directory for `<frame>.exr` (R, G, B, A = opacity, Z = depth) and `<frame>.png`.
    #[arg(long, value_name = "DIR")]
    out: PathBuf,
}

/// Renders every camera and writes the EXR and PNG files.
pub fn run(args: &RenderArgs) -> Result<()> {
    let volume = RadianceVolume::load_safetensors(&args.volume)?;
    let frames = load_transforms(&args.cameras, Some((args.width, args.height)))?;
    let sampler = match (args.samples, args.per_voxel) {
        (_, Some(per_voxel)) => Sampler::PerVoxel { per_voxel },
        (samples, None) => Sampler::Uniform {
            samples: samples.unwrap_or(128),
        },
    };
    let cfg = RenderConfig::default()
        .with_sampler(sampler)
        .with_epsilon(args.epsilon)
        .with_skip_empty(!args.no_skip);
    let cfg = match args.background {
        Some(colour) => cfg.with_background(colour),
        None => cfg,
    };
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    for (i, frame) in frames.iter().enumerate() {
        let stem = frame_stem(frame.file_path.as_deref(), i);
        let start = std::time::Instant::now();
        let image = render_image(&volume, &frame.camera, &cfg)?;
        let (exr, png) = (
            args.out.join(format!("{stem}.exr")),
            args.out.join(format!("{stem}.png")),
        );
        image.write_exr(&exr)?;
        image.write_png(&png)?;
        println!(
            "{} and {} ({:.2} s)",
            exr.display(),
            png.display(),
            start.elapsed().as_secs_f32()
        );
    }
    Ok(())
}

/// Names a frame's output after its image file (`./train/r_3.png` -> `r_3`), or `view_007`.
fn frame_stem(file_path: Option<&str>, index: usize) -> String {
    file_path
        .and_then(|p| Path::new(p).file_stem())
        .map(|s| s.to_string_lossy().into_owned())
        .filter(|s| !s.is_empty())
        .unwrap_or_else(|| format!("view_{index:03}"))
}

/// Parses `--background R,G,B`: three numbers in [0, 1].
fn background(text: &str) -> std::result::Result<[f32; 3], String> {
    let expected = || format!("expected three numbers R,G,B in [0, 1], got {text:?}");
    let parts = text
        .split(',')
        .map(|part| part.trim().parse::<f32>())
        .collect::<std::result::Result<Vec<_>, _>>()
        .map_err(|_| expected())?;
    match <[f32; 3]>::try_from(parts) {
        Ok(colour) if colour.iter().all(|c| (0.0..=1.0).contains(c)) => Ok(colour),
        _ => Err(expected()),
    }
}

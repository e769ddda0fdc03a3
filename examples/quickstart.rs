//! The quickstart: bake the built-in "standing stones" scene into a radiance volume, save it,
//! export it for Blender (OpenVDB) and compositing tools (EXR slices), and render four views.
//!
//! ```text
//! cargo run --release --example quickstart [-- --out DIR --resolution N --size PIXELS]
//! ```
//!
//! Everything goes to `./out/quickstart/` by default; every path written is printed.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result};
use glam::Vec3;
use rgbd_dataset::scenes::{Scene, StandingStones};
use volgen::prelude::*;
use volrender::{render_image, Camera, RenderConfig, Sampler};

struct Options {
    out: PathBuf,
    resolution: usize,
    size: usize,
}

fn parse_options() -> Result<Options> {
    let mut opts = Options {
        out: PathBuf::from("out/quickstart"),
        resolution: 96,
        size: 256,
    };
    let mut args = std::env::args().skip(1);
    while let Some(flag) = args.next() {
        let value = args
            .next()
            .with_context(|| format!("{flag} needs a value"))?;
        match flag.as_str() {
            "--out" => opts.out = PathBuf::from(value),
            "--resolution" => {
                opts.resolution = value
                    .parse()
                    .context("--resolution: expected a number of voxels")?
            }
            "--size" => {
                opts.size = value
                    .parse()
                    .context("--size: expected a number of pixels")?
            }
            other => anyhow::bail!("unknown flag {other} (expected --out, --resolution, --size)"),
        }
    }
    Ok(opts)
}

/// Four views around the scene at 30 degrees elevation, on the paper's camera radius and FOV.
fn views(size: usize) -> Result<Vec<Camera>> {
    let fov = volrender::PAPER_FOV_DEG.to_radians();
    (0..4)
        .map(|i| {
            let azimuth = (45.0 + 90.0 * i as f32).to_radians();
            let elevation = 30f32.to_radians();
            let eye = volrender::PAPER_RADIUS
                * Vec3::new(
                    elevation.cos() * azimuth.cos(),
                    elevation.cos() * azimuth.sin(),
                    elevation.sin(),
                );
            Ok(Camera::look_at(eye, Vec3::ZERO, Vec3::Z, size, size, fov)?)
        })
        .collect()
}

/// Writes the cameras as a NeRF `transforms.json`, so `volgen render` can re-render them.
fn write_transforms(path: &Path, cameras: &[Camera], fov: f32) -> Result<()> {
    let frames: Vec<serde_json::Value> = cameras
        .iter()
        .enumerate()
        .map(|(i, c)| {
            let rows: Vec<[f32; 4]> = (0..4).map(|r| c.c2w.row(r).to_array()).collect();
            serde_json::json!({ "file_path": format!("view_{i}"), "transform_matrix": rows })
        })
        .collect();
    let doc = serde_json::json!({ "camera_angle_x": fov, "frames": frames });
    std::fs::write(path, serde_json::to_string_pretty(&doc)?)
        .with_context(|| format!("writing {}", path.display()))
}

fn main() -> Result<()> {
    let opts = parse_options()?;
    std::fs::create_dir_all(&opts.out)
        .with_context(|| format!("creating {}", opts.out.display()))?;
    let mut written = Vec::new();

    let start = Instant::now();
    let volume = StandingStones::new(7).to_volume(GridDims::cube(opts.resolution))?;
    println!(
        "baked the standing-stones scene at {0}^3 in {1:.2} s",
        opts.resolution,
        start.elapsed().as_secs_f32()
    );

    let native = opts.out.join("stones.safetensors");
    volume.save_safetensors(&native)?;
    written.push(native);

    let vdb = opts.out.join("stones.vdb");
    let stats = volume.write_vdb().to_file(&vdb)?;
    println!(
        "OpenVDB: {} leaves, {} active voxels",
        stats.leaves, stats.active_voxels
    );
    written.push(vdb);

    let slices = opts.out.join("exr_slices");
    std::fs::create_dir_all(&slices)?;
    let files = volume
        .write_exr_slices()
        .half(true)
        .to_dir(&slices, "stones")?;
    println!("EXR slices: {} files", files.len());
    written.push(slices.join("stones.json"));

    let cameras = views(opts.size)?;
    let transforms = opts.out.join("cameras.json");
    write_transforms(&transforms, &cameras, volrender::PAPER_FOV_DEG.to_radians())?;
    written.push(transforms);
    let cfg = RenderConfig::default()
        .with_sampler(Sampler::Uniform { samples: 128 })
        .with_background([1.0; 3]);
    for (i, camera) in cameras.iter().enumerate() {
        let start = Instant::now();
        let image = render_image(&volume, camera, &cfg)?;
        let png = opts.out.join(format!("view_{i}.png"));
        image.write_png(&png)?;
        println!(
            "rendered view {i} ({0}x{0}) in {1:.2} s",
            opts.size,
            start.elapsed().as_secs_f32()
        );
        written.push(png);
    }

    println!("\nwrote:");
    for path in &written {
        println!("  {}", path.display());
    }
    println!("  {} ({} EXR slices)", slices.display(), files.len());
    println!("\nnext: open stones.vdb in Blender (File > Import > OpenVDB), or try");
    println!(
        "  cargo run --release -- render {} --cameras {} --width 128 --height 128 --out {}",
        opts.out.join("stones.safetensors").display(),
        opts.out.join("cameras.json").display(),
        opts.out.join("renders").display()
    );
    Ok(())
}

//! What a perfect generator would score on the sample metrics of `volgen eval`: scenes drawn from
//! the very distribution the stones dataset comes from (the built-in stones scene with other
//! layout seeds), rendered from the dataset's own cameras and compared with its views exactly as
//! `volgen eval` compares generated scenes (its default 4 views, 108^2 colour, 54^2 opacity).
//!
//! Generated scenes vary the real one, so they cannot score 0 on patch SWD, colour SWD or
//! floaters: stones that stand elsewhere cover sky pixels of the real view. These numbers are the
//! floor a generator of new stone circles can reach, and the diversity such scenes have.
//!
//! With a third argument `GRID`, two more rows hold the same scenes as a generator of `GRID^3`
//! volumes could at best make them: each layout fitted directly at that size (`volgen fit`'s
//! defaults, 1000 steps; cached in DIR) and rendered from the same cameras as `volgen eval`
//! renders generated volumes (uniform sampling at `tiny`'s samples per voxel; colour without an
//! upsampler). The layout-0 row scores the grid's own cost on the real scene: the soft edges of
//! a coarse grid cover sky pixels too.
//!
//! ```bash
//! cargo run --release -p research --example reference_scores -- /tmp/reference 8
//! cargo run --release -p research --example reference_scores -- /tmp/reference 8 28
//! ```

use std::path::PathBuf;

use candle_core::{Device, Tensor};
use radiance_volume::RadianceVolume;
use rgbd_dataset::scenes::StandingStones;
use rgbd_dataset::{write_dataset, Dataset, DatasetSpec};
use scene_metrics::{colour_swd, diversity_mv, floaters, patch_swd_mv};
use singrav::TrainConfig;
use volrender::{render, Camera, Rays, RenderConfig, Sampler};
use volume_fit::{fit_volume, FitConfig};

/// `volgen eval`'s defaults: views compared, colour and opacity sizes for `tiny`.
const VIEWS: usize = 4;
const COLOUR_SIZE: usize = 108;
const OPACITY_SIZE: usize = 54;

type Result<T> = std::result::Result<T, Box<dyn std::error::Error>>;

fn main() -> Result<()> {
    let mut args = std::env::args().skip(1);
    let dir = PathBuf::from(
        args.next()
            .ok_or("usage: reference_scores DIR [SCENES [GRID]]")?,
    );
    let scenes: u64 = args.next().map_or(Ok(8), |s| s.parse())?;
    let grid: Option<usize> = args.next().map(|s| s.parse()).transpose()?;
    let device = Device::Cpu;
    // Seed 0's cameras for every layout: `volgen scene stones` uses the seed for both.
    let spec = DatasetSpec::default();
    let background = [1.0, 1.0, 1.0];
    let whole = |layout: u64| -> Result<Dataset> {
        let out = dir.join(format!("stones-{layout}"));
        if !out.join("transforms.json").exists() {
            write_dataset(&StandingStones::new(layout), &out, &spec)?;
        }
        Ok(Dataset::load(&out.join("transforms.json"), background)?)
    };
    let load = |layout: u64| -> Result<Dataset> {
        let data = whole(layout)?;
        // As `volgen eval` spreads its views over the frames.
        let chosen: Vec<usize> = (0..VIEWS).map(|i| i * data.len() / VIEWS).collect();
        Ok(data.subset(&chosen)?)
    };
    let real = load(0)?;
    let real_colour = real.level(COLOUR_SIZE, COLOUR_SIZE, &device)?.images;
    let real_alpha = real.level(OPACITY_SIZE, OPACITY_SIZE, &device)?.opacity;
    let (mut colour, mut opacity) = (Vec::new(), Vec::new());
    for layout in 1..=scenes {
        let other = load(layout)?;
        colour.push(other.level(COLOUR_SIZE, COLOUR_SIZE, &device)?.images);
        opacity.push(other.level(OPACITY_SIZE, OPACITY_SIZE, &device)?.opacity);
    }
    let row = |what: &str, colour: &[Tensor], opacity: &[Tensor]| -> Result<()> {
        // Diversity needs two scenes at least.
        let diversity = match colour.len() {
            0 | 1 => "-".to_string(),
            _ => format!("{:.3}", diversity_mv(colour, &real_colour)?),
        };
        println!(
            "| {what} | {:.4} | {:.4} | {:.4} | {diversity} |",
            patch_swd_mv(colour, &real_colour)?,
            colour_swd(colour, &real_colour)?,
            floaters(opacity, &real_alpha)?.unwrap_or(f64::NAN),
        );
        Ok(())
    };
    println!("| scenes | patch SWD-MV | colour SWD | floaters | Diversity-MV |");
    println!("|---|---|---|---|---|");
    row(
        &format!("stones layouts 1..={scenes} against layout 0"),
        &colour,
        &opacity,
    )?;
    let Some(grid) = grid else {
        return Ok(());
    };
    let colour_cameras = real.level(COLOUR_SIZE, COLOUR_SIZE, &device)?.cameras;
    let opacity_cameras = real.level(OPACITY_SIZE, OPACITY_SIZE, &device)?.cameras;
    // As many uniform samples per voxel as `tiny`'s finest 3D scale takes.
    let tiny = TrainConfig::preset("tiny")?;
    let per_voxel = match (
        tiny.pyramid.samples.last(),
        tiny.pyramid.volume_sizes.last(),
    ) {
        (Some(&samples), Some(&size)) => samples as f64 / size as f64,
        _ => return Err("the tiny preset has no 3D scale".into()),
    };
    let samples = (per_voxel * grid as f64).round() as usize;
    let (mut colour, mut opacity) = (Vec::new(), Vec::new());
    for layout in 0..=scenes {
        let volume = fitted(&dir, layout, grid, || whole(layout))?;
        colour.push(render_all(&volume, &colour_cameras, samples, false)?);
        opacity.push(render_all(&volume, &opacity_cameras, samples, true)?);
    }
    row(
        &format!("layout 0 fitted at {grid}^3"),
        &colour[..1],
        &opacity[..1],
    )?;
    row(
        &format!("layouts 1..={scenes} fitted at {grid}^3"),
        &colour[1..],
        &opacity[1..],
    )?;
    Ok(())
}

/// Layout `layout` fitted directly at `grid^3` to all of its views (loaded by `data` only when
/// needed), read from DIR when a previous run fitted it.
fn fitted(
    dir: &std::path::Path,
    layout: u64,
    grid: usize,
    data: impl FnOnce() -> Result<Dataset>,
) -> Result<RadianceVolume> {
    let path = dir.join(format!("fit-{layout}-{grid}.safetensors"));
    if path.exists() {
        return Ok(RadianceVolume::load_safetensors(&path)?);
    }
    let data = data()?;
    let config = FitConfig {
        size: grid,
        start_size: FitConfig::default().start_size.min(grid),
        ..FitConfig::default()
    };
    let all: Vec<usize> = (0..data.len()).collect();
    let fit = fit_volume(&data, &all, &config, &mut |_| {})?;
    eprintln!("layout {layout} fitted at {grid}^3 in {:.1} s", fit.seconds);
    fit.volume.save_safetensors(&path)?;
    Ok(fit.volume)
}

/// `volume` rendered from every camera as `volgen eval` renders a generated volume (`samples`
/// uniform samples per ray, white background; `volume_fit::render_views` samples per voxel
/// and gives no opacity): colour `(V, 3, h, w)`, or with `opacity` the opacity `(V, 1, h, w)`.
fn render_all(
    volume: &RadianceVolume,
    cameras: &[Camera],
    samples: usize,
    opacity: bool,
) -> Result<Tensor> {
    let config = RenderConfig::default()
        .with_sampler(Sampler::Uniform { samples })
        .with_background([1.0, 1.0, 1.0])
        .with_opacity(opacity);
    let mut views = Vec::with_capacity(cameras.len());
    for camera in cameras {
        let (w, h) = (camera.width, camera.height);
        let out = render(volume.tensor(), &Rays::from_camera(camera), &config)?;
        let map = match out.opacity {
            Some(alpha) if opacity => alpha.reshape((h, w, 1))?,
            _ => out.rgb.reshape((h, w, 3))?,
        };
        views.push(map.permute((2, 0, 1))?);
    }
    Ok(Tensor::stack(&views, 0)?)
}

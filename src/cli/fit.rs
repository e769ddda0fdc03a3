//! `volgen fit DATASET --size N --out VOLUME.safetensors [--vdb FILE] [--exr-slices DIR]
//! [--steps K | --seconds T] [--holdout N] [--post-activation] [--upsample K]`: reconstruct a
//! dataset's scene directly as one radiance volume (no networks), report PSNR on training and
//! held-out views, and write the volume as `volgen sample` writes scenes.

use std::path::{Path, PathBuf};

use anyhow::{ensure, Context, Result};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use rgbd_dataset::{Bounds, Dataset, DepthKind};
use serde::Serialize;
use singrav::TrainConfig;
use volume_fit::{fit_volume, render_views, view_psnr, FitBudget, FitConfig, FittedVolume};

use super::export::{write_exr_slices, write_vdb, Encoding};
use super::model_io::default_upsample;
use super::train::{load_dataset, scene_bounds, warn_if_beyond_the_cube};

/// Arguments of `volgen fit`.
#[derive(Debug, clap::Args)]
#[command(after_help = "docs/fit.md has measured times and PSNR for the built-in scenes.")]
pub struct FitArgs {
    /// The dataset: a transforms.json or the directory holding it.
    dataset: PathBuf,
    /// Edge of the fitted grid in voxels.
    #[arg(long, default_value_t = 64)]
    size: usize,
    /// Where to write the physical volume (safetensors); `.png` and `.fit.json` go beside it.
    #[arg(long, value_name = "VOLUME.safetensors")]
    out: PathBuf,
    /// Also write the volume as OpenVDB to this file.
    #[arg(long, value_name = "FILE")]
    vdb: Option<PathBuf>,
    /// Also write the volume as a stack of EXR slices into this directory.
    #[arg(long, value_name = "DIR")]
    exr_slices: Option<PathBuf>,
    /// Also write the volume's surface as a coloured mesh to this file (.glb, .gltf, .ply,
    /// .obj), at opacity level `--mesh-level` (also `--mesh-smooth`, `--mesh-decimate`).
    #[arg(long, value_name = "FILE")]
    mesh: Option<PathBuf>,
    #[command(flatten)]
    mesh_flags: super::mesh::MeshFlags,
    /// Optimisation steps (default 1000 when --seconds is not given).
    #[arg(long, value_name = "K", conflicts_with = "seconds")]
    steps: Option<usize>,
    /// Wall-clock budget in seconds instead of a step count.
    #[arg(long, value_name = "T")]
    seconds: Option<f64>,
    /// Keep every N-th view (0, N, 2N, ...) out of the fit and report PSNR on them separately.
    #[arg(long, value_name = "N")]
    holdout: Option<usize>,
    /// Edge of the grid the fit starts from (grown coarse to fine to --size).
    #[arg(long, value_name = "N")]
    start_size: Option<usize>,
    /// Rays per step.
    #[arg(long, default_value_t = FitConfig::default().rays_per_step)]
    rays: usize,
    /// Weight of total variation on raw density (0: off).
    #[arg(long, value_name = "W", default_value_t = FitConfig::default().regularisers.tv_density)]
    tv_density: f32,
    /// Weight of total variation on raw colour (0: off).
    #[arg(long, value_name = "W", default_value_t = FitConfig::default().regularisers.tv_colour)]
    tv_colour: f32,
    /// How the dataset's depth maps measure depth, when its transforms.json does not say
    /// (expected, z or distance; as `volgen train --depth-kind`).
    #[arg(long, value_name = "KIND")]
    depth_kind: Option<DepthKind>,
    /// Where the scene is: `xmin,ymin,zmin,xmax,ymax,zmax` or `auto` (as `volgen train
    /// --bounds`). The volume covers the model's cube around that box, in the scene's own
    /// coordinates; without it, [-1, 1]^3.
    #[arg(long, value_name = "BOX|auto", allow_hyphen_values = true)]
    bounds: Option<Bounds>,
    /// Fit colour and opacity only: the dataset's depth maps are not read (nor is their kind
    /// asked for), unless `--bounds auto` places the scene by them.
    #[arg(long)]
    no_depth: bool,
    /// Render with post-activated density (DVGO's rule: samples activate the interpolated raw
    /// density, so edges can be sharper than a voxel), as a SinGRAV run trained with `--set
    /// rendering.post_activation=true` renders (as `tiny` does). The files hold physical
    /// density per voxel, on a grid --upsample times finer.
    #[arg(long)]
    post_activation: bool,
    /// Write the volume (safetensors, VDB, EXR) on a grid K times finer per axis, K odd, so that
    /// tools interpolating physical density render a post-activated fit as the fit renders it
    /// (as `volgen sample --upsample`; docs/formats.md). Default: 3 with --post-activation,
    /// else 1. The report's PSNR is the fit's own rendering either way.
    #[arg(long, value_name = "K", value_parser = super::model_io::odd_factor)]
    upsample: Option<usize>,
    /// Seed of the ray draws.
    #[arg(long, default_value_t = 0)]
    seed: u64,
}

/// What `VOLUME.fit.json` records.
#[derive(Debug, Serialize)]
struct FitReport<'a> {
    dataset: &'a Path,
    size: usize,
    /// How many times finer per axis than `size` the written volume is (`--upsample`).
    upsample: usize,
    /// Whether the volume was fitted (and is scored) with post-activated density.
    post_activation: bool,
    steps: usize,
    seconds: f64,
    live_fraction: f32,
    training_views: usize,
    /// Mean PSNR (dB) over the training views.
    training_psnr: f64,
    held_out_views: usize,
    /// Mean PSNR (dB) over the held-out views; null without --holdout.
    held_out_psnr: Option<f64>,
    /// Seconds spent rendering the views for the PSNR (not part of `seconds`).
    evaluation_seconds: f64,
    /// PSNR (dB) of every view, by its `file_path`, training views first.
    views: Vec<ViewPsnr>,
}

/// One view's PSNR in `VOLUME.fit.json`.
#[derive(Debug, Serialize)]
struct ViewPsnr {
    file_path: String,
    held_out: bool,
    psnr: f64,
}

/// Fits as the arguments say.
pub fn run(args: &FitArgs) -> Result<()> {
    ensure!(
        args.out.extension().is_some_and(|e| e == "safetensors"),
        "--out {}: expected a file name ending in .safetensors",
        args.out.display()
    );
    if let Some(file) = &args.mesh {
        super::mesh::check_mesh_file(file).context("--mesh")?;
    }
    let mut config = fit_config(args)?;
    let training_config = TrainConfig::preset("tiny")?;
    let depth_kind = if args.no_depth && args.bounds != Some(Bounds::Auto) {
        Some(DepthKind::None)
    } else {
        args.depth_kind
    };
    let dataset = load_dataset(&args.dataset, &training_config, depth_kind)?;
    config.use_depth &= dataset.depth_kind() != DepthKind::None;
    match &args.bounds {
        Some(bounds) => config.aabb = scene_bounds(bounds, &dataset)?.cube(),
        None => warn_if_beyond_the_cube(&dataset),
    }
    let (training, held_out) = match args.holdout {
        Some(every) => dataset.holdout_split(every)?,
        None => ((0..dataset.len()).collect(), Vec::new()),
    };
    let fitted = fit_with_progress(&dataset, &training, &config)?;
    let evaluation_start = std::time::Instant::now();
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    let training_views = view_psnr(&fitted.rendered, &dataset, &training, &config)?;
    let held_out_views = if held_out.is_empty() {
        Vec::new()
    } else {
        view_psnr(&fitted.rendered, &dataset, &held_out, &config)?
    };
    let training_psnr = mean(&training_views);
    let held_out_psnr = (!held_out.is_empty()).then(|| mean(&held_out_views));
    let names = dataset.frame_names();
    let views = training
        .iter()
        .zip(&training_views)
        .map(|(&i, &psnr)| (i, false, psnr))
        .chain(
            held_out
                .iter()
                .zip(&held_out_views)
                .map(|(&i, &psnr)| (i, true, psnr)),
        )
        .map(|(i, held_out, psnr)| ViewPsnr {
            file_path: names[i].clone(),
            held_out,
            psnr,
        })
        .collect();
    let report = FitReport {
        dataset: &args.dataset,
        size: config.size,
        upsample: args
            .upsample
            .unwrap_or_else(|| default_upsample(config.post_activation)),
        post_activation: config.post_activation,
        steps: fitted.steps,
        seconds: fitted.seconds,
        live_fraction: fitted.live_fraction,
        training_views: training.len(),
        training_psnr,
        held_out_views: held_out.len(),
        held_out_psnr,
        evaluation_seconds: evaluation_start.elapsed().as_secs_f64(),
        views,
    };
    println!(
        "fitted {size}^3 in {:.1} s ({} steps): PSNR {:.2} dB over {} training views{}",
        fitted.seconds,
        fitted.steps,
        training_psnr,
        training.len(),
        held_out_psnr
            .map(|p| format!(", {p:.2} dB over {} held-out views", held_out.len()))
            .unwrap_or_default(),
        size = config.size,
    );
    write_outputs(args, &dataset, &fitted, &config, &held_out, &report)
}

/// The fit's settings from the arguments.
fn fit_config(args: &FitArgs) -> Result<FitConfig> {
    let defaults = FitConfig::default();
    let budget = match (args.steps, args.seconds) {
        (_, Some(seconds)) => FitBudget::Seconds(seconds),
        (Some(steps), None) => FitBudget::Steps(steps),
        (None, None) => defaults.budget,
    };
    let config = FitConfig {
        size: args.size,
        start_size: args.start_size.unwrap_or(defaults.start_size),
        budget,
        rays_per_step: args.rays,
        regularisers: volume_fit::Regularisers {
            tv_density: args.tv_density,
            tv_colour: args.tv_colour,
        },
        use_depth: !args.no_depth,
        seed: args.seed,
        post_activation: args.post_activation,
        ..defaults
    };
    config.validate()?;
    Ok(config)
}

/// Fits with a progress bar (step, grid size, batch PSNR, live voxels).
fn fit_with_progress(
    dataset: &Dataset,
    training: &[usize],
    config: &FitConfig,
) -> Result<FittedVolume> {
    let bar = FitBar::new()?;
    let fitted = fit_volume(dataset, training, config, &mut |p| bar.show("the views", p))
        .with_context(|| format!("fitting {}", dataset_name(dataset)))?;
    bar.finish();
    Ok(fitted)
}

/// A progress bar of a fit's steps (grid size, batch PSNR, live voxels).
pub struct FitBar(ProgressBar);

impl FitBar {
    /// A bar on stderr, hidden without a terminal.
    pub fn new() -> Result<Self> {
        let bar = ProgressBar::with_draw_target(Some(1000), ProgressDrawTarget::stderr());
        bar.set_style(
            ProgressStyle::with_template("{elapsed_precise} [{bar:28}] {msg}")
                .context("progress bar template")?
                .progress_chars("=> "),
        );
        Ok(Self(bar))
    }

    /// Shows the progress of the fit of `what`.
    pub fn show(&self, what: &str, p: &volume_fit::FitProgress) {
        self.0.set_position((p.fraction * 1000.0) as u64);
        self.0.set_message(format!(
            "fitting {what}: step {} grid {}^3 batch PSNR {:.2} dB, {:.0}% voxels live",
            p.step,
            p.size,
            p.batch_psnr,
            100.0 * p.live_fraction
        ));
    }

    /// Clears the bar.
    pub fn finish(self) {
        self.0.finish_and_clear();
    }
}

fn dataset_name(dataset: &Dataset) -> String {
    format!(
        "{} views of {}x{}",
        dataset.len(),
        dataset.width(),
        dataset.height()
    )
}

/// Writes the volume, a picture (real views above, fitted below; held-out views first) and
/// the report, plus VDB / EXR slices when asked.
fn write_outputs(
    args: &FitArgs,
    dataset: &Dataset,
    fitted: &FittedVolume,
    config: &FitConfig,
    held_out: &[usize],
    report: &FitReport<'_>,
) -> Result<()> {
    if let Some(dir) = args.out.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    let volume = if report.upsample == 1 {
        fitted.volume.clone()
    } else {
        singrav::export::physical_upsampled(
            &fitted.rendered,
            config.density_interpolation(),
            report.upsample,
        )?
    };
    volume.save_safetensors(&args.out)?;
    let shown: Vec<usize> = held_out
        .iter()
        .copied()
        .chain(0..dataset.len())
        .take(3)
        .collect();
    let views = dataset.subset(&shown)?;
    let level = views.level(views.width(), views.height(), &candle_core::Device::Cpu)?;
    let rendered = render_views(&fitted.rendered, &level.cameras, config)?;
    let row = |t: &candle_core::Tensor| -> Result<Vec<candle_core::Tensor>> {
        Ok((0..shown.len())
            .map(|i| t.get(i))
            .collect::<candle_core::Result<_>>()?)
    };
    let picture = args.out.with_extension("png");
    singrav::picture::write_grid(&picture, &[row(&level.images)?, row(&rendered)?])?;
    let json = args.out.with_extension("fit.json");
    radiance_volume::io::write_bytes_atomic(&json, &serde_json::to_vec_pretty(report)?)?;
    if let Some(vdb) = &args.vdb {
        write_vdb(&volume, vdb, &Encoding::default())?;
    }
    if let Some(dir) = &args.exr_slices {
        let stem = args
            .out
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "volume".into());
        write_exr_slices(&volume, dir, &stem, &Encoding::default())?;
    }
    if let Some(file) = &args.mesh {
        super::mesh::write_mesh(&volume, file, args.mesh_flags.shape())?;
    }
    println!(
        "wrote {} (views: {}, report: {})",
        args.out.display(),
        picture.display(),
        json.display()
    );
    Ok(())
}

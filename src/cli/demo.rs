//! `volgen demo`: the whole pipeline in one command. Builds the default scene's dataset, trains
//! the `tiny` preset, samples four scenes, and writes pictures (input views beside generated
//! ones), VDB files and a summary to `./out/demo`.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result};
use candle_core::Tensor;
use rgbd_dataset::scenes::SceneKind;
use rgbd_dataset::{write_built_in, DatasetSpec};
use serde::Serialize;
use singrav::checkpoint::Checkpoint;
use singrav::sample::Sample;
use singrav::train::{read_log, LogLine, LossTerm, RunOptions};
use singrav::{RunDir, SinGrav};

use super::model_io::Outputs;
use super::sample::{sample_to_dir, Draws, Views};
use super::train::{load_dataset, train_with_progress, TrainOptions};

/// Arguments of `volgen demo`.
#[derive(Debug, clap::Args)]
pub struct DemoArgs {
    /// Output directory [default: out/demo for the stones at `tiny`; another scene or preset
    /// adds its names, as out/demo-hd or out/demo-islands-small, so that one demo never meets
    /// another's run]
    #[arg(long, value_name = "DIR")]
    out: Option<PathBuf>,
    /// The built-in scene to learn.
    #[arg(long, default_value = "stones", value_parser = super::scene::built_in_scenes())]
    scene: SceneKind,
    /// Scenes to generate.
    #[arg(long, default_value_t = 4)]
    count: usize,
    /// Views in the dataset.
    #[arg(long, default_value_t = 100)]
    views: usize,
    /// Edge of the dataset's images (default: the preset's final size, at least 128).
    #[arg(long, value_name = "PIXELS")]
    resolution: Option<usize>,
    #[command(flatten)]
    train: TrainOptions,
}

impl DemoArgs {
    /// The output directory: `--out`, or `out/demo` with the scene and preset named where they
    /// are not the defaults.
    fn out(&self) -> PathBuf {
        self.out
            .clone()
            .unwrap_or_else(|| default_out(self.scene, &self.train.preset))
    }
}

/// `out/demo`, suffixed by the scene unless it is the stones and by the preset unless it is
/// `tiny`: a demo of another scene or preset would find the default run and be refused.
fn default_out(scene: SceneKind, preset: &str) -> PathBuf {
    let mut name = String::from("demo");
    if scene != SceneKind::StandingStones {
        write!(name, "-{}", scene.name()).expect("writing to a String");
    }
    if preset != "tiny" {
        write!(name, "-{preset}").expect("writing to a String");
    }
    Path::new("out").join(name)
}

/// Frames of each sample's turntable GIF.
const DEMO_TURNTABLE_FRAMES: usize = 36;

/// The summary written to `summary.json` (and, readably, `summary.md`).
#[derive(Debug, Serialize)]
struct Summary {
    scene: String,
    preset: String,
    dataset_seconds: f64,
    training_seconds: f64,
    scale_seconds: Vec<f64>,
    scale_peak_mib: Vec<Option<f64>>,
    final_losses: Vec<LogLine>,
    generation_seconds: Vec<f64>,
    /// The paper's Diversity-MV of the samples against the input views they are shown beside.
    diversity_mv: Option<f64>,
    overview: PathBuf,
    dataset: PathBuf,
    model: PathBuf,
    samples: PathBuf,
    /// An animated camera orbit per sample.
    turntables: Vec<PathBuf>,
    scale_pictures: Vec<PathBuf>,
}

/// Runs the demo.
pub fn run(args: &DemoArgs) -> Result<()> {
    let config = args.train.config()?;
    let out = args.out();
    let dataset_dir = out.join("dataset");
    let run_dir = out.join("run");
    let run = RunDir::new(&run_dir);
    let samples_dir = out.join("samples");

    let started = Instant::now();
    let resolution = args
        .resolution
        .unwrap_or_else(|| config.final_image_size().max(128));
    let spec = DatasetSpec {
        views: args.views,
        resolution,
        seed: config.run.seed,
        ..DatasetSpec::default()
    };
    println!(
        "1/3 rendering the `{}` scene: {} views at {resolution}^2 -> {}",
        args.scene.name(),
        spec.views,
        dataset_dir.display()
    );
    write_built_in(args.scene, config.run.seed, &dataset_dir, &spec)
        .with_context(|| format!("writing the dataset to {}", dataset_dir.display()))?;
    let dataset_seconds = started.elapsed().as_secs_f64();
    let dataset = load_dataset(&dataset_dir, &config, None)?;

    // A run left by an earlier demo with the same settings is continued, not overwritten.
    let resume = args.train.resume || run.has_checkpoint();
    println!(
        "2/3 training the `{}` preset ({} scales, {} iterations){} -> {}",
        config.preset,
        config.scales(),
        config.total_iterations(),
        if resume { ", resuming" } else { "" },
        run_dir.display()
    );
    let options = RunOptions {
        resume,
        ..args.train.run_options()
    };
    let model = train_with_progress(&config, &dataset, &run_dir, &options)?;
    let state = Checkpoint::load(&run.checkpoint(), model.device())?.state;

    println!(
        "3/3 sampling {} scenes -> {}",
        args.count,
        samples_dir.display()
    );
    let input_views = 3.min(dataset.len());
    let size = model.render_size();
    let cameras = dataset.level(size, size, model.device())?.cameras[..input_views].to_vec();
    let outputs = Outputs {
        vdb: cfg!(feature = "vdb"),
        exr_slices: cfg!(feature = "exr"),
        upsample: None,
        mesh: None,
        mesh_flags: super::mesh::MeshFlags::default(),
    };
    let views = Views::with_cameras(&model, cameras, Some(DEMO_TURNTABLE_FRAMES))?;
    let draws = Draws {
        count: args.count,
        seed: config.run.seed,
        vary_from: 1,
    };
    let samples = sample_to_dir(&model, &views, draws, &samples_dir, outputs)?;
    let overview = out.join("overview.png");
    let real = input_views_at_sample_size(&model, &dataset, input_views, &samples)?;
    write_overview(&overview, &real, &samples)?;
    let generated: Vec<_> = samples.iter().map(|s| s.views.clone()).collect();
    let diversity_mv = (samples.len() >= 2)
        .then(|| scene_metrics::diversity_mv(&generated, &real))
        .transpose()?;

    let summary = Summary {
        scene: args.scene.name().into(),
        preset: config.preset.clone(),
        dataset_seconds,
        training_seconds: state.scale_seconds.iter().sum(),
        scale_seconds: state.scale_seconds.clone(),
        scale_peak_mib: state.scale_peak_mib.clone(),
        final_losses: last_losses_per_scale(&run)?,
        generation_seconds: samples.iter().map(|s| s.generation_seconds).collect(),
        diversity_mv,
        overview: overview.clone(),
        dataset: dataset_dir,
        model: run_dir.clone(),
        turntables: (0..samples.len())
            .map(|i| samples_dir.join(format!("scene_{i}.gif")))
            .collect(),
        samples: samples_dir,
        scale_pictures: (1..=config.scales())
            .map(|n| run.scale_picture(n))
            .collect(),
    };
    write_summary(&out, &summary)?;
    println!(
        "done: overview {} (top row: input views; below: generated scenes)",
        overview.display()
    );
    println!("      summary  {}", out.join("summary.md").display());
    println!("      volumes  {}", summary.samples.display());
    Ok(())
}

/// Input views in the top row, each generated scene from the same cameras below.
fn write_overview(path: &Path, real: &Tensor, samples: &[Sample]) -> Result<()> {
    let row = |views: &Tensor| -> Result<Vec<Tensor>> {
        Ok((0..views.dim(0)?)
            .map(|v| views.get(v))
            .collect::<candle_core::Result<Vec<_>>>()?)
    };
    let mut rows = vec![row(real)?];
    for sample in samples {
        rows.push(row(&sample.views)?);
    }
    singrav::picture::write_grid(path, &rows)?;
    Ok(())
}

/// The first `views` dataset images at the size of the samples' renderings, `(V, 3, H, W)`.
fn input_views_at_sample_size(
    model: &SinGrav,
    dataset: &rgbd_dataset::Dataset,
    views: usize,
    samples: &[Sample],
) -> Result<Tensor> {
    let size = match samples.first() {
        Some(s) => s.views.dim(3)?,
        None => model.render_size(),
    };
    let level = dataset.level(size, size, model.device())?;
    Ok(level.images.narrow(0, 0, views)?)
}

/// The last logged losses of every scale.
fn last_losses_per_scale(run: &RunDir) -> Result<Vec<LogLine>> {
    let mut last: Vec<LogLine> = Vec::new();
    for line in read_log(run)? {
        match last.last_mut() {
            Some(prev) if prev.scale == line.scale => *prev = line,
            _ => last.push(line),
        }
    }
    Ok(last)
}

/// Writes summary.json and summary.md.
fn write_summary(dir: &Path, summary: &Summary) -> Result<()> {
    write_text(
        &dir.join("summary.json"),
        &serde_json::to_string_pretty(summary)?,
    )?;
    let mut md = String::new();
    writeln!(
        md,
        "# volgen demo: `{}` scene, `{}` preset\n",
        summary.scene, summary.preset
    )?;
    writeln!(
        md,
        "- dataset: {} ({:.0} s)",
        summary.dataset.display(),
        summary.dataset_seconds
    )?;
    writeln!(
        md,
        "- model: {} (training {:.0} s)",
        summary.model.display(),
        summary.training_seconds
    )?;
    writeln!(md, "- overview: {}", summary.overview.display())?;
    writeln!(md, "- generated volumes: {}", summary.samples.display())?;
    let links: Vec<String> = summary
        .turntables
        .iter()
        .map(|gif| {
            let shown = gif.strip_prefix(dir).unwrap_or(gif).display().to_string();
            let name = gif.file_stem().unwrap_or_default().to_string_lossy();
            format!("[{name}]({shown})")
        })
        .collect();
    writeln!(md, "- turntables (animated GIF): {}\n", links.join(", "))?;
    md.push_str(&loss_table(summary));
    let times: Vec<String> = summary
        .generation_seconds
        .iter()
        .map(|s| format!("{s:.3}"))
        .collect();
    writeln!(md, "\nGeneration time per scene (s): {}", times.join(", "))?;
    if let Some(d) = summary.diversity_mv {
        writeln!(
            md,
            "\nDiversity-MV of the samples over the overview's views: {d:.3}"
        )?;
    }
    write_text(&dir.join("summary.md"), &md)
}

/// The time, memory and last logged losses of every scale as a Markdown table, "-" where a
/// loss is not computed at that scale; a loss the run never computed has no column.
fn loss_table(summary: &Summary) -> String {
    let value = |i: usize, term: LossTerm| summary.final_losses.get(i)?.losses.get(term);
    let scales = summary.scale_seconds.len();
    // Only the terms this run computed somewhere (the 3D critic's, for one, are rare).
    let columns: Vec<LossTerm> = LossTerm::ALL
        .into_iter()
        .filter(|&term| (0..scales).any(|i| value(i, term).is_some()))
        .collect();
    let mut table = String::from("| scale | seconds | peak MiB | iterations |");
    for term in &columns {
        table.push_str(&format!(" {} |", term.describe()));
    }
    table.push_str(&format!("\n|{}\n", "---|".repeat(4 + columns.len())));
    for (i, seconds) in summary.scale_seconds.iter().enumerate() {
        let mib = summary.scale_peak_mib.get(i).copied().flatten();
        // The log's iteration counts from 0.
        let iterations = summary
            .final_losses
            .get(i)
            .map_or("-".into(), |l| (l.iteration + 1).to_string());
        table.push_str(&format!(
            "| {} | {seconds:.0} | {} | {iterations} |",
            i + 1,
            mib.map_or("n/a".into(), |m| format!("{m:.0}")),
        ));
        for &term in &columns {
            let cell = value(i, term).map_or("-".into(), |v| format!("{v:.4}"));
            table.push_str(&format!(" {cell} |"));
        }
        table.push('\n');
    }
    table
}

/// Writes a text file atomically.
fn write_text(path: &Path, text: &str) -> Result<()> {
    Ok(radiance_volume::io::write_bytes_atomic(
        path,
        text.as_bytes(),
    )?)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn demos_of_other_scenes_and_presets_default_to_their_own_directories() {
        assert_eq!(
            default_out(SceneKind::StandingStones, "tiny"),
            Path::new("out/demo")
        );
        assert_eq!(
            default_out(SceneKind::StandingStones, "hd"),
            Path::new("out/demo-hd")
        );
        let islands = "islands".parse().unwrap();
        assert_eq!(
            default_out(islands, "small"),
            Path::new("out/demo-islands-small")
        );
        assert_eq!(default_out(islands, "tiny"), Path::new("out/demo-islands"));
    }
}

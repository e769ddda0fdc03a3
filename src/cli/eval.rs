//! `volgen eval RUN... --dataset DIR [--scenes N] [--views V] [--seed S] [--inception FILE]`:
//! the quality numbers of trained models. Renders the fixed-noise reconstruction V* and
//! generated scenes from cameras of the training dataset and compares them with the dataset's
//! images from the same cameras (docs/metrics.md defines every number). With several runs, a
//! Markdown table compares them, a row per run.

use std::path::{Path, PathBuf};

use super::model_io::load_model;
use super::train::{device, load_dataset};
use anyhow::{ensure, Context, Result};
use candle_core::{Device, Tensor};
use rand::SeedableRng;
use serde::Serialize;
use singrav::checkpoint::checkpoint_path;
use singrav::dataset::{Dataset, DepthKind};
use singrav::metrics::{
    colour_swd_per_scene, depth_rmse, diversity_mv, floaters_per_scene, mean_psnr, mean_ssim,
    patch_swd_per_scene, sifid_mv, Estimate, InceptionBlock1, PATCH_SWD_MIN_SIDE,
};
use singrav::SinGrav;

/// Arguments of `volgen eval`.
#[derive(Debug, clap::Args)]
#[command(after_help = "The paper evaluates 50 scenes from 40 views each \
    (--scenes 50 --views 40); the defaults take about half a minute on the tiny \
    preset. docs/metrics.md explains the numbers and how to convert InceptionV3's weights.")]
pub struct EvalArgs {
    /// Trained models: run directories or their checkpoint.safetensors. With several, a
    /// Markdown table compares them (each still writes eval.json in its run directory).
    #[arg(required = true, value_name = "RUN")]
    models: Vec<PathBuf>,
    /// The dataset the models were trained on (a transforms.json or its directory): its images
    /// are the real views. Required because a run does not record where its dataset was.
    #[arg(long, value_name = "DIR")]
    dataset: PathBuf,
    /// How the dataset's depth maps measure depth, when its transforms.json does not say (as
    /// `volgen train --depth-kind`).
    #[arg(long, value_name = "KIND")]
    depth_kind: Option<DepthKind>,
    /// Scenes to generate (at least 2; the paper: 50). Every sample metric is shown with its
    /// standard error over these scenes; with 32 a `tiny` run's floaters vary by about 10%
    /// between noise seeds, with 8 by twice that (docs/metrics.md, "How precise the sample
    /// metrics are").
    #[arg(long, default_value_t = 32)]
    scenes: usize,
    /// Dataset views to compare, evenly spaced over its frames (the paper: 40); as many of the
    /// training and of the held-out frames for the reconstruction.
    #[arg(long, default_value_t = 4)]
    views: usize,
    /// Seed of the noise; the same seed gives the scenes `volgen sample --seed` gives.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// InceptionV3 weights (torchvision's names, safetensors) for SIFID-MV; without them
    /// SIFID-MV is not computed.
    #[arg(long, value_name = "FILE")]
    inception: Option<PathBuf>,
    /// Where to write the numbers as JSON (default: eval.json in the run directory); only
    /// with a single run.
    #[arg(long, value_name = "FILE")]
    out: Option<PathBuf>,
    /// With several runs of one setting (other seeds), end the table with a row of each
    /// number's mean over the runs and its standard error over them: runs differ far more
    /// than one evaluation's scenes do.
    #[arg(long)]
    mean: bool,
}

/// What `eval.json` holds. Infinite PSNRs (exact reconstructions) are written as null.
#[derive(Debug, Serialize)]
struct Evaluation {
    model: PathBuf,
    dataset: PathBuf,
    scenes: usize,
    seed: u64,
    /// The dataset frames (their `file_path`) the generated scenes were seen from.
    views: Vec<String>,
    /// Edge of the compared colour images in pixels (the model's final size).
    image_size: usize,
    /// Edge of the depth and opacity maps (the last 3D scale's rendering size).
    depth_size: usize,
    /// The run's `--holdout N`, if it had one.
    holdout: Option<usize>,
    /// The training frames the reconstruction was seen from.
    reconstruction_views: Vec<String>,
    /// dB, higher is better.
    reconstruction_psnr: f64,
    /// 1 is a perfect reconstruction.
    reconstruction_ssim: f64,
    /// World units, lower is better.
    reconstruction_depth_rmse: f64,
    /// The held-out frames (empty without a holdout).
    held_out_views: Vec<String>,
    held_out_psnr: Option<f64>,
    held_out_ssim: Option<f64>,
    held_out_depth_rmse: Option<f64>,
    /// dB: V* itself, the finest 3D scale's volume, rendered from every training view at the
    /// dataset's resolution as `volgen fit` measures its volumes, by the run's density rule
    /// (post-activated runs: as `volgen fit --post-activation`), so the two compare on equal
    /// terms (no upsampler).
    volume_psnr: f64,
    /// How many training views `volume_psnr` averages.
    volume_views: usize,
    /// The same over every held-out view (null without a holdout).
    held_out_volume_psnr: Option<f64>,
    /// Lower is closer to the real views' patch statistics; null for views too small for its
    /// pyramid.
    patch_swd_mv: Option<f64>,
    /// One standard error of `patch_swd_mv` over the generated scenes (as for every
    /// `_stderr` below: the value's spread over repeated draws of as many scenes).
    patch_swd_mv_stderr: Option<f64>,
    /// Lower is closer to the real views' colours.
    colour_swd: f64,
    colour_swd_stderr: f64,
    /// Mean opacity where the real views are empty; null when no real pixel is empty.
    floaters: Option<f64>,
    floaters_stderr: Option<f64>,
    /// Higher is more varied; 0 when every scene is the same.
    diversity_mv: f64,
    /// The jackknife standard error over scenes; null with fewer than 3 scenes.
    diversity_mv_stderr: Option<f64>,
    /// Lower is closer to the real views' statistics; null without InceptionV3 weights.
    sifid_mv: Option<f64>,
    inception: Option<PathBuf>,
}

/// How closely V* reproduces a set of real views.
struct Fit {
    views: Vec<String>,
    psnr: f64,
    ssim: f64,
    depth_rmse: f64,
}

/// Evaluates as the arguments say.
pub fn run(args: &EvalArgs) -> Result<()> {
    ensure!(
        args.scenes >= 2,
        "--scenes must be at least 2: Diversity-MV is a spread over scenes"
    );
    ensure!(args.views >= 1, "--views must be at least 1");
    ensure!(
        !args.mean || args.models.len() >= 2,
        "--mean needs at least 2 runs (seeds of one setting) to average, got {}",
        args.models.len()
    );
    ensure!(
        args.out.is_none() || args.models.len() == 1,
        "--out names one file, for a single run; with several runs each writes eval.json in \
         its run directory"
    );
    let device = device()?;
    // Weights first: a wrong path should fail before minutes of generation.
    let block = args
        .inception
        .as_ref()
        .map(|path| InceptionBlock1::from_safetensors(path, &device))
        .transpose()?;
    let mut evaluations = Vec::with_capacity(args.models.len());
    for model in &args.models {
        let evaluation = evaluate(model, args, block.as_ref(), &device)
            .with_context(|| format!("evaluating {}", model.display()))?;
        let out = args
            .out
            .clone()
            .unwrap_or_else(|| run_dir(model).join("eval.json"));
        radiance_volume::io::write_bytes_atomic(
            &out,
            format!("{}\n", serde_json::to_string_pretty(&evaluation)?).as_bytes(),
        )
        .with_context(|| format!("writing {}", out.display()))?;
        if args.models.len() == 1 {
            print_report(&evaluation);
        }
        eprintln!("wrote {}", out.display());
        evaluations.push(evaluation);
    }
    if evaluations.len() > 1 {
        print!("{}", markdown_table(&evaluations, args.mean));
    }
    Ok(())
}

/// Every number of one model.
fn evaluate(
    model_path: &Path,
    args: &EvalArgs,
    block: Option<&InceptionBlock1>,
    device: &Device,
) -> Result<Evaluation> {
    let model = load_model(model_path)?;
    let scene_dataset = load_dataset(&args.dataset, model.config(), args.depth_kind)?;
    // The model renders in its own cube: a run trained with --bounds sees the views there.
    // Kept apart from the scene's copy only when the two differ.
    let in_cube = match &model.config().bounds {
        Some(bounds) => Some(scene_dataset.in_model_cube(bounds)?),
        None => None,
    };
    let dataset = in_cube.as_ref().unwrap_or(&scene_dataset);
    ensure!(
        args.views <= dataset.len(),
        "--views {} is more than the {} frames of {}",
        args.views,
        dataset.len(),
        args.dataset.display()
    );
    let holdout = model.config().holdout;
    let (training, held_out) = match holdout {
        Some(every) => dataset
            .holdout_split(every)
            .with_context(|| format!("the run held out every {every}-th view"))?,
        None => ((0..dataset.len()).collect(), Vec::new()),
    };

    let v_star = model.reconstruct()?;
    let reconstruction = fit(
        &model,
        &v_star,
        dataset,
        &spread(&training, args.views),
        device,
    )?;
    let held = (!held_out.is_empty())
        .then(|| {
            fit(
                &model,
                &v_star,
                dataset,
                &spread(&held_out, args.views),
                device,
            )
        })
        .transpose()?;
    // In the scene's coordinates, with the density rule the run renders by.
    let training_volume_psnr = model.volume_psnr(&v_star, &scene_dataset, &training)?;
    let held_out_volume_psnr = (!held_out.is_empty())
        .then(|| model.volume_psnr(&v_star, &scene_dataset, &held_out))
        .transpose()?;

    let all: Vec<usize> = (0..dataset.len()).collect();
    let chosen = dataset.subset(&spread(&all, args.views))?;
    let size = model.render_size();
    let coarse = chosen.level(size, size, device)?;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(args.seed);
    let mut views: Vec<Tensor> = Vec::with_capacity(args.scenes);
    let mut opacity: Vec<Tensor> = Vec::with_capacity(args.scenes);
    for i in 0..args.scenes {
        // As `SinGrav::sample` draws them: scene i here is scene i of `volgen sample`.
        let raw = model.generate_random(&mut rng)?;
        let maps = model.render_maps(&raw, &coarse.cameras)?;
        views.push(maps.rgb);
        opacity.push(maps.opacity);
        eprintln!("scene {}/{} rendered", i + 1, args.scenes);
    }
    // The upsampler, when trained, doubles the renderings: compare at the size they came out.
    let image_size = views[0].dim(3)?;
    let real = chosen.level(image_size, image_size, device)?.images;
    let patch_swd = (image_size >= PATCH_SWD_MIN_SIDE)
        .then(|| Estimate::mean_of(&patch_swd_per_scene(&views, &real)?))
        .transpose()
        .context("patch_swd_mv of the generated scenes")?;
    let colour = Estimate::mean_of(&colour_swd_per_scene(&views, &real)?)
        .context("colour_swd of the generated scenes")?;
    let floaters = floaters_per_scene(&opacity, &coarse.opacity)?
        .map(|per_scene| Estimate::mean_of(&per_scene))
        .transpose()
        .context("floaters of the generated scenes")?;
    // The jackknife computes Diversity-MV over all scenes too; below 3 scenes it has no error.
    let (diversity, diversity_stderr) = if args.scenes >= 3 {
        let estimate = Estimate::jackknife(&views, |scenes| diversity_mv(scenes, &real))
            .context("Diversity-MV of the generated scenes")?;
        (estimate.value, Some(estimate.stderr))
    } else {
        (diversity_mv(&views, &real)?, None)
    };

    Ok(Evaluation {
        model: model_path.to_path_buf(),
        dataset: args.dataset.clone(),
        scenes: args.scenes,
        seed: args.seed,
        views: chosen.frame_names().to_vec(),
        image_size,
        depth_size: size,
        holdout,
        reconstruction_views: reconstruction.views,
        reconstruction_psnr: reconstruction.psnr,
        reconstruction_ssim: reconstruction.ssim,
        reconstruction_depth_rmse: reconstruction.depth_rmse,
        held_out_views: held.as_ref().map(|h| h.views.clone()).unwrap_or_default(),
        held_out_psnr: held.as_ref().map(|h| h.psnr),
        held_out_ssim: held.as_ref().map(|h| h.ssim),
        held_out_depth_rmse: held.as_ref().map(|h| h.depth_rmse),
        volume_psnr: training_volume_psnr,
        volume_views: training.len(),
        held_out_volume_psnr,
        patch_swd_mv: patch_swd.map(|e| e.value),
        patch_swd_mv_stderr: patch_swd.map(|e| e.stderr),
        colour_swd: colour.value,
        colour_swd_stderr: colour.stderr,
        floaters: floaters.map(|e| e.value),
        floaters_stderr: floaters.map(|e| e.stderr),
        diversity_mv: diversity,
        diversity_mv_stderr: diversity_stderr,
        sifid_mv: block.map(|b| sifid_mv(&views, &real, b)).transpose()?,
        inception: args.inception.clone(),
    })
}

/// V* against the dataset's `frames`: colour at the final size, depth at the 3D pyramid's.
fn fit(
    model: &SinGrav,
    v_star: &Tensor,
    dataset: &Dataset,
    frames: &[usize],
    device: &Device,
) -> Result<Fit> {
    let chosen = dataset.subset(frames)?;
    let size = model.render_size();
    let coarse = chosen.level(size, size, device)?;
    let maps = model.render_maps(v_star, &coarse.cameras)?;
    let image_size = maps.rgb.dim(3)?;
    let real = chosen.level(image_size, image_size, device)?.images;
    Ok(Fit {
        views: chosen.frame_names().to_vec(),
        psnr: mean_psnr(&maps.rgb, &real)?,
        ssim: mean_ssim(&maps.rgb, &real)?,
        depth_rmse: depth_rmse(&maps.depth, &coarse.depths)?,
    })
}

/// `count` of `indices` evenly spaced (all of them when there are fewer).
fn spread(indices: &[usize], count: usize) -> Vec<usize> {
    let count = count.min(indices.len());
    (0..count)
        .map(|i| indices[i * indices.len() / count])
        .collect()
}

/// The labelled lines of one model's numbers.
fn print_report(e: &Evaluation) {
    println!(
        "{} scenes x {} views at {}x{} (seed {})",
        e.scenes,
        e.views.len(),
        e.image_size,
        e.image_size,
        e.seed
    );
    println!(
        "reconstruction_psnr:       {:.2} dB  (V* on {} training views; higher = closer)",
        e.reconstruction_psnr,
        e.reconstruction_views.len()
    );
    println!(
        "reconstruction_ssim:       {:.4}  (1 = identical)",
        e.reconstruction_ssim
    );
    println!(
        "reconstruction_depth_rmse: {:.4}  (world units; lower = closer)",
        e.reconstruction_depth_rmse
    );
    println!(
        "volume_psnr:               {:.2} dB  (V*'s volume on all {} training views, as `volgen \
         fit` scores its volumes)",
        e.volume_psnr, e.volume_views
    );
    if let Some(psnr) = e.held_out_volume_psnr {
        println!("held_out_volume_psnr:      {psnr:.2} dB");
    }
    match (e.held_out_psnr, e.held_out_ssim, e.held_out_depth_rmse) {
        (Some(psnr), Some(ssim), Some(depth)) => {
            println!(
                "held_out_psnr:             {psnr:.2} dB  (V* on {} held-out views)",
                e.held_out_views.len()
            );
            println!("held_out_ssim:             {ssim:.4}");
            println!("held_out_depth_rmse:       {depth:.4}");
        }
        _ => println!("held_out:                  none (train with --holdout N to measure)"),
    }
    match e.patch_swd_mv {
        Some(p) => println!(
            "patch_swd_mv:              {}  (lower = patches closer to the real views')",
            cell(Some(p), e.patch_swd_mv_stderr, 4)
        ),
        None => println!(
            "patch_swd_mv:              not computed: views of {} pixels are below its \
             {PATCH_SWD_MIN_SIDE}",
            e.image_size
        ),
    }
    println!(
        "colour_swd:                {}  (lower = colours closer to the real views')",
        cell(Some(e.colour_swd), Some(e.colour_swd_stderr), 4)
    );
    match e.floaters {
        Some(f) => println!(
            "floaters:                  {}  (mean opacity where the real views are empty)",
            cell(Some(f), e.floaters_stderr, 4)
        ),
        None => println!("floaters:                  not computed: no real pixel is empty"),
    }
    println!(
        "Diversity-MV:              {}  (higher = more varied scenes)",
        cell(Some(e.diversity_mv), e.diversity_mv_stderr, 4)
    );
    println!(
        "                           (± one standard error over the {} scenes: their sampling \
         noise, not a difference between runs)",
        e.scenes
    );
    match e.sifid_mv {
        Some(s) => {
            println!("SIFID-MV:                  {s:.4}  (lower = closer to the real views)")
        }
        None => println!(
            "SIFID-MV:                  not computed: it needs InceptionV3 weights (--inception \
             FILE.safetensors); docs/metrics.md shows how to convert torchvision's"
        ),
    }
}

/// One Markdown table, a row per model (as the paper's Table 1), "-" where a number was not
/// computed; the sample metrics with their standard errors over scenes. With `mean`, a last row
/// of each column's mean over the models and its standard error over them ("-" where a model
/// lacks the number or it is infinite).
fn markdown_table(evaluations: &[Evaluation], mean: bool) -> String {
    let mut table = String::from(
        "| run | PSNR (dB) | SSIM | depth RMSE | volume PSNR (dB) | held-out PSNR | held-out SSIM | \
         patch SWD-MV | colour SWD | floaters | Diversity-MV | SIFID-MV |\n\
         |---|---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    for e in evaluations {
        let cells: Vec<String> = columns(e)
            .iter()
            .map(|&(value, stderr, digits)| cell(value, stderr, digits))
            .collect();
        table.push_str(&format!(
            "| {} | {} |\n",
            e.model.display(),
            cells.join(" | ")
        ));
    }
    if mean {
        let per_model: Vec<_> = evaluations.iter().map(columns).collect();
        let cells: Vec<String> = (0..per_model[0].len())
            .map(|column| {
                let digits = per_model[0][column].2;
                let values: Option<Vec<f64>> = per_model
                    .iter()
                    .map(|model| model[column].0.filter(|v| v.is_finite()))
                    .collect();
                match values.map(|v| Estimate::mean_of(&v)) {
                    Some(Ok(e)) => cell(Some(e.value), Some(e.stderr), digits),
                    _ => "-".to_string(),
                }
            })
            .collect();
        table.push_str(&format!(
            "| mean ± s.e. of {} runs | {} |\n",
            evaluations.len(),
            cells.join(" | ")
        ));
    }
    table
}

/// The table's numbers of one model, in its column order: value, standard error over scenes
/// (the sample metrics), decimals shown.
fn columns(e: &Evaluation) -> [(Option<f64>, Option<f64>, usize); 11] {
    [
        (Some(e.reconstruction_psnr), None, 2),
        (Some(e.reconstruction_ssim), None, 4),
        (Some(e.reconstruction_depth_rmse), None, 4),
        (Some(e.volume_psnr), None, 2),
        (e.held_out_psnr, None, 2),
        (e.held_out_ssim, None, 4),
        (e.patch_swd_mv, e.patch_swd_mv_stderr, 4),
        (Some(e.colour_swd), Some(e.colour_swd_stderr), 4),
        (e.floaters, e.floaters_stderr, 4),
        (Some(e.diversity_mv), e.diversity_mv_stderr, 4),
        (e.sifid_mv, None, 4),
    ]
}

/// A number with `digits` decimals and, when known, its standard error; "-" when not computed.
fn cell(value: Option<f64>, stderr: Option<f64>, digits: usize) -> String {
    match (value, stderr) {
        (Some(value), Some(stderr)) => format!("{value:.digits$} ± {stderr:.digits$}"),
        (Some(value), None) => format!("{value:.digits$}"),
        (None, _) => "-".to_string(),
    }
}

/// The run directory of `model` (the directory itself, or the one holding the checkpoint).
fn run_dir(model: &Path) -> PathBuf {
    checkpoint_path(model)
        .parent()
        .map(Path::to_path_buf)
        .unwrap_or_default()
}

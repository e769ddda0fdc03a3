//! `volgen eval RUN... --dataset DIR [--scenes N] [--views V] [--seed S] [--inception FILE]
//! [--family N] [--vary-from N]`: the quality numbers of trained models. Renders the fixed-noise
//! reconstruction V* and generated scenes from cameras of the training dataset and compares them
//! with the dataset's images from the same cameras (docs/metrics.md defines every number). With
//! several runs, a Markdown table compares them, a row per run. With `--family N`, N other
//! layouts of the dataset's built-in scene are scored the same way, as a reference row.

use std::path::{Path, PathBuf};

use super::model_io::load_model;
use super::train::{device, load_dataset};
use anyhow::{ensure, Context, Result};
use rgbd_dataset::DepthKind;
use scene_metrics::{Estimate, InceptionBlock1, PATCH_SWD_MIN_SIDE};
use serde::Serialize;
use singrav::eval::{evaluate, EvalConfig, Evaluation, LayoutReference, SceneScores};

/// Arguments of `volgen eval`.
#[derive(Debug, clap::Args)]
#[command(after_help = "The paper evaluates 50 scenes from 40 views each \
    (--scenes 50 --views 40); the defaults take about half a minute on the tiny \
    preset. docs/metrics.md explains the numbers and how to convert InceptionV3's weights.")]
pub struct EvalArgs {
    /// Trained models: run directories or their checkpoints. With several, a Markdown table
    /// compares them (each still writes its numbers into its run directory).
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
    /// The scene's volume the generated volumes' layout distance is measured against: `fit` (a
    /// direct fit of the dataset's training views, made first: about 10 s on `tiny`) or
    /// `vstar` (the model's reconstruction).
    #[arg(long, value_name = "fit|vstar", default_value = "fit")]
    layout_reference: LayoutReference,
    /// Also score N other layouts of the dataset's built-in scene (a dataset `volgen scene` or
    /// `volgen demo` wrote), rendered from the same views with the same functions: what a
    /// perfect generator of that kind of scene scores, a reference row.
    #[arg(long, value_name = "N", default_value_t = 0)]
    family: usize,
    /// The coarsest 3D scale whose noise varies (as `volgen sample --vary-from`): scales below
    /// it keep V*'s layout.
    #[arg(long, value_name = "N", default_value_t = 1)]
    vary_from: usize,
    /// InceptionV3 weights (torchvision's names, safetensors) for SIFID-MV; without them
    /// SIFID-MV is not computed.
    #[arg(long, value_name = "FILE")]
    inception: Option<PathBuf>,
    /// Where to write the numbers as JSON (default: into the run directory, docs/training.md's
    /// "Files of a run"); only with a single run.
    #[arg(long, value_name = "FILE")]
    out: Option<PathBuf>,
    /// With several runs of one setting (other seeds), end the table with a row of each
    /// number's mean over the runs and its standard error over them: runs differ far more
    /// than one evaluation's scenes do.
    #[arg(long)]
    mean: bool,
}

/// What the numbers' JSON file holds: the paths, then the library's numbers.
#[derive(Debug, Serialize)]
struct EvalFile {
    model: PathBuf,
    dataset: PathBuf,
    #[serde(flatten)]
    numbers: Evaluation,
    inception: Option<PathBuf>,
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
        "--out names one file, for a single run; with several runs each writes its numbers \
         into its run directory"
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
        let evaluation = evaluate_model(model, args, block.as_ref())
            .with_context(|| format!("evaluating {}", model.display()))?;
        let out = args
            .out
            .clone()
            .unwrap_or_else(|| singrav::RunDir::of_model(model).eval());
        radiance_volume::io::write_bytes_atomic(
            &out,
            format!("{}\n", serde_json::to_string_pretty(&evaluation)?).as_bytes(),
        )
        .with_context(|| format!("writing {}", out.display()))?;
        if args.models.len() == 1 {
            print_report(&evaluation.numbers);
        }
        eprintln!("wrote {}", out.display());
        evaluations.push(evaluation);
    }
    if evaluations.len() > 1 {
        print!("{}", markdown_table(&evaluations, args.mean));
    }
    Ok(())
}

/// Every number of one model, with the paths it came from.
fn evaluate_model(
    model_path: &Path,
    args: &EvalArgs,
    block: Option<&InceptionBlock1>,
) -> Result<EvalFile> {
    let model = load_model(model_path)?;
    let dataset = load_dataset(&args.dataset, model.config(), args.depth_kind)?;
    let config = EvalConfig {
        scenes: args.scenes,
        views: args.views,
        seed: args.seed,
        layout_reference: args.layout_reference,
        vary_from: args.vary_from,
        family: args.family,
    };
    let numbers = evaluate(&model, &dataset, &config, block, &mut |i, n| {
        eprintln!("scene {i}/{n} rendered")
    })
    .with_context(|| format!("with the dataset {}", args.dataset.display()))?;
    Ok(EvalFile {
        model: model_path.to_path_buf(),
        dataset: args.dataset.clone(),
        numbers,
        inception: args.inception.clone(),
    })
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
    match e.reconstruction_depth_rmse {
        Some(rmse) => {
            println!("reconstruction_depth_rmse: {rmse:.4}  (world units; lower = closer)")
        }
        None => println!("reconstruction_depth_rmse: none (the dataset has no depth maps)"),
    }
    println!(
        "volume_psnr:               {:.2} dB  (V*'s volume on all {} training views, as `volgen \
         fit` scores its volumes)",
        e.volume_psnr, e.volume_views
    );
    if let Some(psnr) = e.held_out_volume_psnr {
        println!("held_out_volume_psnr:      {psnr:.2} dB");
    }
    match (e.held_out_psnr, e.held_out_ssim) {
        (Some(psnr), Some(ssim)) => {
            println!(
                "held_out_psnr:             {psnr:.2} dB  (V* on {} held-out views)",
                e.held_out_views.len()
            );
            println!("held_out_ssim:             {ssim:.4}");
            if let Some(depth) = e.held_out_depth_rmse {
                println!("held_out_depth_rmse:       {depth:.4}");
            }
        }
        _ => println!("held_out:                  none (train with --holdout N to measure)"),
    }
    if e.vary_from > 1 {
        println!(
            "scenes vary from 3D scale {} (the coarser scales keep V*'s noise)",
            e.vary_from
        );
    }
    print_scores(&e.samples, e.image_size, &e.layout_reference);
    if let Some(v_star) = e.reconstruction_layout_distance {
        println!("reconstruction_layout:     {v_star:.4}  (V*'s own layout distance from the fit)");
    }
    if let Some(v_star) = e.reconstruction_layout_distance_by_position {
        println!("reconstruction_position:   {v_star:.4}  (the same by position alone)");
    }
    if let Some(v_star) = e.reconstruction_misplaced_matter {
        println!("reconstruction_misplaced:  {v_star:.4}  (V*'s own matter out of place against the fit)");
    }
    let objects = |o: &singrav::eval::ObjectCount| {
        format!("{} (largest holds {:.3})", o.count, o.largest_share)
    };
    println!(
        "scene objects:             {} in the {}{}",
        objects(&e.reference_objects),
        match e.layout_reference.as_str() {
            "fit" => "fit",
            _ => "V*",
        },
        e.true_objects
            .as_ref()
            .map_or(String::new(), |truth| format!(
                ", {} in the built-in scene itself",
                objects(truth)
            ))
    );
    println!(
        "                           (± one standard error over the {} scenes: their sampling \
         noise, not a difference between runs)",
        e.scenes
    );
    if let Some(family) = &e.family {
        println!(
            "family: {} other layouts of the built-in `{}` scene (seeds {}..={}), seen from the \
             same views: what a perfect generator of this scene scores",
            family.seeds.len(),
            family.scene,
            family.seeds.first().copied().unwrap_or_default(),
            family.seeds.last().copied().unwrap_or_default()
        );
        print_scores(&family.scores, e.image_size, &e.layout_reference);
    }
}

/// The labelled lines of a set of scenes' sample metrics.
fn print_scores(e: &SceneScores, image_size: usize, layout_reference: &str) {
    match e.patch_swd_mv {
        Some(p) => println!(
            "patch_swd_mv:              {}  (lower = patches closer to the real views')",
            cell(Some(p), e.patch_swd_mv_stderr, 4)
        ),
        None => println!(
            "patch_swd_mv:              not computed: views of {image_size} pixels are below \
             its {PATCH_SWD_MIN_SIDE}"
        ),
    }
    println!(
        "colour_swd:                {}  (lower = colours closer to the real views')",
        cell(Some(e.colour_swd), e.colour_swd_stderr, 4)
    );
    match e.floaters {
        Some(f) => println!(
            "floaters:                  {}  (mean opacity where the real views are empty)",
            cell(Some(f), e.floaters_stderr, 4)
        ),
        None => println!("floaters:                  not computed: no real pixel is empty"),
    }
    println!(
        "layout_distance:           {}  (lower = matter placed as in the scene; against {})",
        cell(Some(e.layout_distance), e.layout_distance_stderr, 4),
        match layout_reference {
            "fit" => "a direct fit of the training views",
            _ => "V*",
        }
    );
    println!(
        "layout_by_position:        {}  (the same by position alone: matter moved, not tinted)",
        cell(
            Some(e.layout_distance_by_position),
            e.layout_distance_by_position_stderr,
            4
        )
    );
    println!(
        "misplaced_matter:          {}  (share of matter where the scene has none of its colour \
         nearby; lower = arrangement kept)",
        cell(Some(e.misplaced_matter), e.misplaced_matter_stderr, 4)
    );
    println!(
        "objects:                   {}  (separate solid things above the ground; largest holds {} \
         of the object matter, at most {:.3})",
        cell(Some(e.objects), e.objects_stderr, 2),
        cell(
            Some(e.largest_object_share),
            e.largest_object_share_stderr,
            3
        ),
        e.largest_object_share_max
    );
    println!(
        "Diversity-MV:              {}  (higher = more varied scenes)",
        cell(e.diversity_mv, e.diversity_mv_stderr, 4)
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
/// computed; the sample metrics with their standard errors over scenes. With `mean`, a row of
/// each column's mean over the models and its standard error over them ("-" where a model
/// lacks the number or it is infinite). With a family, its row ends the table.
fn markdown_table(evaluations: &[EvalFile], mean: bool) -> String {
    let mut table = String::from(
        "| run | PSNR (dB) | SSIM | depth RMSE | volume PSNR (dB) | held-out PSNR | held-out SSIM | \
         patch SWD-MV | colour SWD | floaters | layout | layout by position | misplaced | objects | \
         largest object | Diversity-MV | SIFID-MV |\n\
         |---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    for e in evaluations {
        let cells: Vec<String> = columns(&e.numbers)
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
        let per_model: Vec<_> = evaluations.iter().map(|e| columns(&e.numbers)).collect();
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
    if let Some(family) = evaluations.iter().find_map(|e| e.numbers.family.as_ref()) {
        let cells: Vec<String> = std::iter::repeat_n("-".to_string(), 6)
            .chain(
                sample_columns(&family.scores)
                    .iter()
                    .map(|&(value, stderr, digits)| cell(value, stderr, digits)),
            )
            .collect();
        table.push_str(&format!(
            "| family: {} other layouts of `{}` | {} |\n",
            family.seeds.len(),
            family.scene,
            cells.join(" | ")
        ));
    }
    table
}

/// A table column's number: value, standard error over scenes (the sample metrics), decimals
/// shown.
type Column = (Option<f64>, Option<f64>, usize);

/// The table's numbers of one model, in its column order.
fn columns(e: &Evaluation) -> Vec<Column> {
    let mut columns = vec![
        (Some(e.reconstruction_psnr), None, 2),
        (Some(e.reconstruction_ssim), None, 4),
        (e.reconstruction_depth_rmse, None, 4),
        (Some(e.volume_psnr), None, 2),
        (e.held_out_psnr, None, 2),
        (e.held_out_ssim, None, 4),
    ];
    columns.extend(sample_columns(&e.samples));
    columns
}

/// The sample metrics' columns of the table.
fn sample_columns(e: &SceneScores) -> [Column; 10] {
    [
        (e.patch_swd_mv, e.patch_swd_mv_stderr, 4),
        (Some(e.colour_swd), e.colour_swd_stderr, 4),
        (e.floaters, e.floaters_stderr, 4),
        (Some(e.layout_distance), e.layout_distance_stderr, 4),
        (
            Some(e.layout_distance_by_position),
            e.layout_distance_by_position_stderr,
            4,
        ),
        (Some(e.misplaced_matter), e.misplaced_matter_stderr, 4),
        (Some(e.objects), e.objects_stderr, 2),
        (
            Some(e.largest_object_share),
            e.largest_object_share_stderr,
            3,
        ),
        (e.diversity_mv, e.diversity_mv_stderr, 4),
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

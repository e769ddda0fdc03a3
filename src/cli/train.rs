//! `volgen train DATASET --out RUN [--preset tiny] [--resume] [--vgg19 WEIGHTS]`: train
//! SinGRAV on a `transforms.json` RGB-D dataset, with a progress bar, a JSON-lines log and
//! checkpoints.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use radiance_volume::RadianceVolume;
use rgbd_dataset::{Dataset, DepthKind, LoadOptions, SceneBounds};
use singrav::checkpoint::CHECKPOINT_FILE;
use singrav::train::{
    train, Control, Event, LossTerm, Progress, RunOptions, StepLosses, TrainOutcome,
};
use singrav::{SinGrav, SwdFeatures, TrainConfig};
use volume_fit::FitConfig;

/// Arguments of `volgen train`.
#[derive(Debug, clap::Args)]
pub struct TrainArgs {
    /// The dataset: a transforms.json or the directory holding it.
    dataset: PathBuf,
    /// The run directory (checkpoint, config.json, log.jsonl, samples/).
    #[arg(long, value_name = "DIR")]
    out: PathBuf,
    /// How the dataset's depth maps measure depth, overriding its `depth_kind`: expected
    /// (volgen's own), z (planar, as Blender's Z pass and most RGB-D sensors) or distance (ray
    /// length to the surface).
    #[arg(long, value_name = "KIND")]
    depth_kind: Option<DepthKind>,
    /// Where the scene is, in the dataset's coordinates: `xmin,ymin,zmin,xmax,ymax,zmax`, or
    /// `auto` for the box of the depth maps' points (1st to 99th percentile plus 5%; printed).
    /// Training maps it into the model's cube; sample, animate and edit then work in the
    /// scene's coordinates. Without it the scene must lie in [-1, 1]^3. Give it again with
    /// --resume.
    #[arg(long, value_name = "BOX|auto", allow_hyphen_values = true)]
    bounds: Option<String>,
    /// Depth from a fit of the views (the paper's NeRF-depth), for photos without depth maps:
    /// fits the training views without depth (`volgen fit`'s defaults, 64^3; written to
    /// RUN/depth_fit.safetensors and reused by --resume), renders its depth from every camera
    /// and trains with it, pixels the fit leaves thin left out of the depth loss. Replaces
    /// the dataset's own depth maps where it has some. Give it again with --resume.
    #[arg(long, conflicts_with = "no_depth")]
    depth_from_fit: bool,
    /// Steps of the fit --depth-from-fit runs (default: `volgen fit`'s).
    #[arg(long, value_name = "K", requires = "depth_from_fit")]
    depth_fit_steps: Option<usize>,
    #[command(flatten)]
    options: TrainOptions,
}

/// Training settings shared by `train` and `demo`.
#[derive(Debug, Clone, clap::Args)]
pub struct TrainOptions {
    /// Preset: paper and paper-island (GPU), hd (the paper's 126^3 and 320^2, about 40 minutes
    /// on 2 cores), small (216^2, about 11), tiny (108^2, about 10) or micro (seconds).
    #[arg(long, default_value = "tiny")]
    pub preset: String,
    /// Continue a killed run from its last checkpoint (with the same settings; a run whose
    /// reconstruction is not fitted yet may change --reconstruction-fit, so a finished run can
    /// be given that fit).
    #[arg(long)]
    pub resume: bool,
    /// Ablation: the number of scales N (keeps the coarsest N - 1 3D scales).
    #[arg(long, value_name = "N")]
    pub scales: Option<usize>,
    /// Ablation: train without the SWD loss at the last scale.
    #[arg(long)]
    pub no_swd: bool,
    /// The last scale's SWD loss compares VGG-19 features (as the paper) with these weights:
    /// safetensors with torchvision's names (docs/swd-loss.md shows the conversion). Without
    /// it, a weights-free patch pyramid. Give it again with --resume.
    #[arg(long, value_name = "FILE", conflicts_with = "no_swd")]
    pub vgg19: Option<PathBuf>,
    /// Ablation: train without the CSG grid at the coarsest scale.
    #[arg(long)]
    pub no_csg: bool,
    /// Ablation: train without depth supervision.
    #[arg(long)]
    pub no_depth: bool,
    /// Ablation: train without opacity supervision (the opacity reconstruction term, the
    /// critics' opacity channel and the samples' opacity terms: height profile, binary prior),
    /// as the paper.
    #[arg(long)]
    pub no_opacity: bool,
    /// The paper's dense finer scales: every voxel may change at every 3D scale (turns off the
    /// preset's active set, `active_set.from_scale`; see docs/training.md).
    #[arg(long)]
    pub dense: bool,
    /// Weight of the colour-distribution loss of generated scenes at the 3D scales (sliced W2
    /// between the pixel colours of a sample's rendering and the real view's; default: the
    /// preset's).
    #[arg(long, value_name = "W")]
    pub lambda_colour: Option<f64>,
    /// Views of the reconstruction loss per generator step at the 3D scales (default: the
    /// preset's).
    #[arg(long, value_name = "N")]
    pub reconstruction_views: Option<usize>,
    /// Conv layers L of every generator and critic (default: the preset's); the receptive
    /// field is 2L + 1 voxels or pixels.
    #[arg(long, value_name = "L")]
    pub layers: Option<usize>,
    /// Adam learning rate of generators and critics (default: the preset's).
    #[arg(long, value_name = "LR")]
    pub learning_rate: Option<f64>,
    /// Iterations at every scale, the first quarter reconstruction-only (default: the preset's
    /// schedule).
    #[arg(long, value_name = "N")]
    pub iterations: Option<usize>,
    /// Seed of every random draw.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Also compare every 3D scale's reconstruction in 3D with this directly fitted volume
    /// (from `volgen fit`; copied into the run) instead of fitting one.
    #[arg(long, value_name = "VOLUME", conflicts_with = "fit")]
    pub fitted: Option<PathBuf>,
    /// Fit a volume to the dataset first (`volgen fit` at twice the finest 3D scale's edge, or
    /// at that edge for post-activated runs; written to RUN/fitted.safetensors) and train
    /// against it as --fitted does. A configuration that compares with a fitted volume (`--set
    /// losses.fitted=W`) does this without the flag.
    #[arg(long)]
    pub fit: bool,
    /// Steps of the fit --fit runs (default: `volgen fit`'s).
    #[arg(long, value_name = "K", requires = "fit")]
    pub fit_steps: Option<usize>,
    /// Weight of the fitted-volume comparison (default: the configuration's; with --fitted or
    /// --fit on one without, 10).
    #[arg(long, value_name = "W")]
    pub lambda_fitted: Option<f64>,
    /// Weight of a 3D patch critic's adversarial term: it judges generated volumes against a
    /// fitted volume (--fitted, or one fitted first) at every 3D scale, or up to
    /// `--set critics.volume_until_scale=N` (1: where the layout is made). Default 0: no 3D
    /// critic.
    #[arg(long, value_name = "W")]
    pub lambda_volume_critic: Option<f64>,
    /// The 3D critic also judges opacity-weighted colour per voxel, not only opacity.
    #[arg(long, requires = "lambda_volume_critic")]
    pub volume_critic_colour: bool,
    /// After the last scale, fit the reconstruction V* directly to the views for K steps, every
    /// network frozen, and keep the difference as V*'s detail (0: none; default: the
    /// preset's). Generated scenes are not changed by it.
    #[arg(long, value_name = "K")]
    pub reconstruction_fit: Option<usize>,
    /// Set any setting of the configuration, by its dotted path in config.json, to a JSON
    /// value, after the preset and the flags above: `--set losses.rgb=50 --set
    /// pyramid.channels=32`. Repeatable.
    #[arg(long = "set", value_name = "PATH=VALUE")]
    pub settings: Vec<String>,
    /// Keep every N-th view (0, N, 2N, ...) out of training; `volgen eval` reports the
    /// reconstruction on them separately (fit against 3D consistency). Recorded in the run.
    #[arg(long, value_name = "N")]
    pub holdout: Option<usize>,
}

/// The fitted-volume weight `--fitted` and `--fit` use on a configuration without one, unless told
/// otherwise.
pub const DEFAULT_LAMBDA_FITTED: f64 = 10.0;

impl TrainOptions {
    /// The configuration these options describe.
    pub fn config(&self) -> Result<TrainConfig> {
        let mut config = TrainConfig::preset(&self.preset)?;
        if let Some(scales) = self.scales {
            config = config.with_scales(scales)?;
        }
        if let Some(iterations) = self.iterations {
            config = config.with_iterations(iterations);
        }
        config.ablations.use_swd &= !self.no_swd;
        if self.vgg19.is_some() {
            config.losses.swd_features = SwdFeatures::Vgg19;
        }
        config.ablations.use_csg &= !self.no_csg;
        config.ablations.use_depth &= !self.no_depth;
        if let Some(views) = self.reconstruction_views {
            config = config.with_reconstruction_views(views);
        }
        if self.dense {
            config.active_set.from_scale = None;
        }
        if let Some(weight) = self.lambda_colour {
            config.losses.colour_distribution = weight;
        }
        if let Some(layers) = self.layers {
            config.pyramid.layers = layers;
        }
        if let Some(rate) = self.learning_rate {
            config.schedule.learning_rate = rate;
        }
        if self.no_opacity {
            config.losses.opacity = 0.0;
            config.critics.opacity = false;
            config.losses.height_profile = 0.0;
            config.losses.opacity_binary = 0.0;
        }
        config.run.seed = self.seed;
        if let Some(weight) = self.lambda_fitted {
            config.losses.fitted = weight;
        } else if (self.fitted.is_some() || self.fit) && config.losses.fitted == 0.0 {
            config.losses.fitted = DEFAULT_LAMBDA_FITTED;
        }
        if let Some(weight) = self.lambda_volume_critic {
            config.losses.volume_critic = weight;
        }
        config.critics.volume_colour |= self.volume_critic_colour;
        if let Some(steps) = self.reconstruction_fit {
            config.schedule.reconstruction_fit_steps = steps;
        }
        config.run.holdout = self.holdout;
        for setting in &self.settings {
            let (field, value) = setting.split_once('=').with_context(|| {
                format!("--set {setting}: expected PATH=VALUE, e.g. --set losses.rgb=50")
            })?;
            config = config
                .with_setting(field.trim(), value.trim())
                .with_context(|| format!("--set {setting}"))?;
        }
        config.validate()?;
        Ok(config)
    }

    /// How the run goes beside its configuration: resume or not, the VGG-19 weights.
    /// With `--fit`, or a configuration that compares with a fitted volume and no `--fitted`,
    /// runs the fit into `run_dir` (unless resuming a run that has its copy).
    pub fn run_options(
        &self,
        config: &TrainConfig,
        dataset: &Dataset,
        run_dir: &Path,
    ) -> Result<RunOptions> {
        let needs_fit = config.losses.fitted > 0.0 || config.losses.volume_critic > 0.0;
        let fitted_volume = match (&self.fitted, self.fit || needs_fit) {
            (Some(path), _) => Some(path.clone()),
            (None, true) => Some(fit_for_training(
                config,
                self.fit_steps,
                dataset,
                run_dir,
                self.resume,
            )?),
            (None, false) => None,
        };
        Ok(RunOptions {
            resume: self.resume,
            vgg19_weights: self.vgg19.clone(),
            fitted_volume,
            ..RunOptions::default()
        })
    }
}

/// Fits `dataset`'s training views into `run_dir/fitted.safetensors` as
/// [`TrainConfig::fit_config`] says (with a progress bar), or reuses the file
/// there when resuming.
fn fit_for_training(
    config: &TrainConfig,
    steps: Option<usize>,
    dataset: &Dataset,
    run_dir: &Path,
    resume: bool,
) -> Result<PathBuf> {
    let path = run_dir.join("fitted.safetensors");
    if resume && path.exists() {
        return Ok(path);
    }
    let size = config.fit_config().size;
    let fitted = super::fit::with_fit_progress(dataset, |observer| {
        Ok(singrav::train::fit_training_target(
            config, dataset, steps, observer,
        )?)
    })?;
    std::fs::create_dir_all(run_dir).with_context(|| format!("creating {}", run_dir.display()))?;
    fitted.volume.save_safetensors(&path)?;
    eprintln!(
        "fitted {size}^3 to the dataset in {:.1} s: {}",
        fitted.seconds,
        path.display()
    );
    Ok(path)
}

/// `dataset` with depth from a fit of its training views without depth
/// ([`Dataset::with_depth_from`]): the fit is written to `RUN/depth_fit.safetensors`, or read
/// from there when resuming.
fn with_depth_from_fit(
    config: &TrainConfig,
    dataset: Dataset,
    args: &TrainArgs,
) -> Result<Dataset> {
    let run_dir = &args.out;
    let path = run_dir.join("depth_fit.safetensors");
    let volume = if args.options.resume && path.exists() {
        RadianceVolume::load_safetensors(&path)?
    } else {
        let defaults = FitConfig::default();
        let mut fit_config = FitConfig {
            use_depth: false,
            budget: args
                .depth_fit_steps
                .map_or(defaults.budget, volume_fit::FitBudget::Steps),
            ..defaults
        };
        if let Some(bounds) = &config.run.bounds {
            fit_config.aabb = bounds.cube();
        }
        let training = match config.run.holdout {
            Some(every) => dataset.holdout_split(every)?.0,
            None => (0..dataset.len()).collect(),
        };
        let fitted = super::fit::with_fit_progress(&dataset, |observer| {
            Ok(volume_fit::fit_volume(
                &dataset,
                &training,
                &fit_config,
                observer,
            )?)
        })?;
        std::fs::create_dir_all(run_dir)
            .with_context(|| format!("creating {}", run_dir.display()))?;
        fitted.volume.save_safetensors(&path)?;
        eprintln!(
            "fitted {}^3 to the views without depth in {:.1} s for their depth: {}",
            fit_config.size,
            fitted.seconds,
            path.display()
        );
        fitted.volume
    };
    let (dataset, coverage) = dataset.with_depth_from(&volume)?;
    eprintln!(
        "depth from the fit: {} of {} foreground pixels ({:.1}%) are too thin in it and left \
         out of the depth loss",
        coverage.holes,
        coverage.foreground,
        100.0 * coverage.holes as f64 / coverage.foreground.max(1) as f64
    );
    Ok(dataset)
}

/// Trains as the arguments say.
pub fn run(args: &TrainArgs) -> Result<()> {
    let mut config = args.options.config()?;
    config.run.depth_from_fit = args.depth_from_fit;
    let mut dataset = load_dataset(&args.dataset, &config, args.depth_kind)?;
    config.run.bounds = scene_bounds(args.bounds.as_deref(), &dataset)?;
    if args.depth_from_fit {
        dataset = with_depth_from_fit(&config, dataset, args)?;
    }
    // Without depth maps the depth loss and the critics' depth channel have nothing to see.
    config.ablations.use_depth &= dataset.depth_kind() != DepthKind::None;
    let options = args.options.run_options(&config, &dataset, &args.out)?;
    if options.resume && args.out.is_dir() && !args.out.join(CHECKPOINT_FILE).exists() {
        eprintln!(
            "{} holds no checkpoint yet: training from the beginning",
            args.out.display()
        );
    }
    train_with_progress(&config, &dataset, &args.out, &options)?;
    println!("trained model: {}", args.out.display());
    Ok(())
}

/// The scene's box as `--bounds` gives it (printed), or `None` without the flag (with a warning
/// when the depth shows a scene outside the model's cube).
pub fn scene_bounds(flag: Option<&str>, dataset: &Dataset) -> Result<Option<SceneBounds>> {
    let Some(flag) = flag else {
        warn_if_outside_the_cube(dataset);
        return Ok(None);
    };
    let bounds = match flag {
        "auto" => dataset.auto_bounds()?,
        given => given
            .parse::<SceneBounds>()
            .context("--bounds: expected xmin,ymin,zmin,xmax,ymax,zmax or auto")?,
    };
    let cube = bounds.cube();
    println!(
        "scene bounds {bounds} (--bounds {flag}); the model's cube [-1, 1]^3 is {:?}..{:?} in \
         the scene",
        cube.min.to_array(),
        cube.max.to_array()
    );
    Ok(Some(bounds))
}

/// How far past the model's cube `[-1, 1]^3` the depth maps' `auto` box may reach before
/// training without `--bounds` warns (the box has a 5% margin; the built-in scenes' reach 1.09).
const CUBE_SLACK: f32 = 1.25;

/// Warns when the scene the depth maps show is not in the model's cube: trained without
/// `--bounds`, it would be cut off or squeezed.
fn warn_if_outside_the_cube(dataset: &Dataset) {
    let Ok(seen) = dataset.auto_bounds() else {
        return;
    };
    if seen
        .min
        .iter()
        .chain(&seen.max)
        .any(|v| v.abs() > CUBE_SLACK)
    {
        eprintln!(
            "warning: the depth maps' points span {seen}, beyond the model's cube [-1, 1]^3; \
             give --bounds auto (or the scene's box) to place the scene"
        );
    }
}

/// Loads and checks a dataset for training with `config`, its depth read as `depth_kind` when
/// given (else as the dataset says), and reports the pixels left out of the depth loss.
pub fn load_dataset(
    path: &Path,
    config: &TrainConfig,
    depth_kind: Option<DepthKind>,
) -> Result<Dataset> {
    let options = LoadOptions {
        background: config.rendering.background,
        depth_kind,
    };
    let dataset = Dataset::load_with(path, &options)
        .with_context(|| format!("loading the dataset {}", path.display()))?;
    let left_out = dataset.depth_left_out();
    if dataset.depth_kind() == DepthKind::None {
        eprintln!(
            "{}: no depth maps (depth_kind none): training and fitting go without the depth loss",
            path.display()
        );
    } else if left_out > 0 {
        eprintln!(
            "{}: {left_out} pixels with colour but no depth (depth_kind {}) are left out of the \
             depth loss",
            path.display(),
            dataset.depth_kind()
        );
    }
    Ok(dataset)
}

/// Trains with a progress bar (scale, step, losses, time left) and a line per scale.
pub fn train_with_progress(
    config: &TrainConfig,
    dataset: &Dataset,
    run_dir: &Path,
    options: &RunOptions,
) -> Result<Box<SinGrav>> {
    let total = config.total_iterations() as u64;
    let bar = ProgressBar::with_draw_target(Some(total), ProgressDrawTarget::stderr());
    bar.set_style(
        ProgressStyle::with_template(
            "{elapsed_precise} [{bar:28}] {pos}/{len} {msg} | left ~{eta}",
        )
        .context("progress bar template")?
        .progress_chars("=> "),
    );
    let mut observer = |p: &Progress| {
        bar.set_position((config.iterations_before(p.scale) + p.iteration) as u64);
        match &p.event {
            Event::Step => bar.set_message(format!(
                "scale {}/{} step {}/{} {}",
                p.scale,
                p.scales,
                p.iteration,
                p.iterations,
                format_losses(&p.losses)
            )),
            Event::Checkpoint(_) => {}
            Event::ScaleDone(picture) => print_line(
                &bar,
                format!(
                    "scale {}/{} done in {:.0} s; samples: {}",
                    p.scale,
                    p.scales,
                    p.scale_seconds,
                    picture.display()
                ),
            ),
            Event::ReconstructionFitting => bar.set_message(format!(
                "fitting the reconstruction to the views ({} steps)",
                config.schedule.reconstruction_fit_steps
            )),
            Event::ReconstructionFitted { batch_psnr } => print_line(
                &bar,
                format!(
                    "reconstruction fitted to the views in {:.0} s (last batch {batch_psnr:.2} dB)",
                    p.scale_seconds
                ),
            ),
        }
        Control::Continue
    };
    let outcome = train(config, dataset, run_dir, options, &device()?, &mut observer)
        .with_context(|| format!("training into {}", run_dir.display()))?;
    bar.finish_and_clear();
    match outcome {
        TrainOutcome::Finished(model) => Ok(model),
        TrainOutcome::Stopped => anyhow::bail!("training stopped before the last scale"),
    }
}

/// Prints a line above the progress bar (or on stderr when the bar is hidden, without a
/// terminal: the per-scale lines still matter there).
fn print_line(bar: &ProgressBar, line: String) {
    if bar.is_hidden() {
        eprintln!("{line}");
    } else {
        bar.println(line);
    }
}

/// The device networks train on: the first CUDA GPU when built with the `cuda` feature, else
/// the CPU.
pub fn device() -> Result<candle_core::Device> {
    #[cfg(feature = "cuda")]
    return Ok(candle_core::Device::new_cuda(0)?);
    #[cfg(not(feature = "cuda"))]
    Ok(candle_core::Device::Cpu)
}

/// The losses of a step, compactly: the colour reconstruction first, then every other term
/// computed.
fn format_losses(l: &StepLosses) -> String {
    let mut parts = vec![format!(
        "rec {:.4}",
        l.get(LossTerm::Colour).unwrap_or_default()
    )];
    for (term, value) in l.iter().filter(|(term, _)| *term != LossTerm::Colour) {
        parts.push(format!("{} {value:.3}", short_name(term)));
    }
    parts.join(" ")
}

/// A loss term's name on the progress bar.
fn short_name(term: LossTerm) -> &'static str {
    match term {
        LossTerm::Critic => "D",
        LossTerm::Penalty => "gp",
        LossTerm::Adversarial => "adv",
        LossTerm::Colour => "rec",
        LossTerm::Depth => "depth",
        LossTerm::Swd => "swd",
        LossTerm::Fitted => "fit",
        LossTerm::Opacity => "opacity",
        LossTerm::ColourDistribution => "colour",
        LossTerm::ChromaDistribution => "chroma",
        LossTerm::HeightProfile => "height",
        LossTerm::OpacityBinary => "binary",
        LossTerm::VolumeCritic => "D3",
        LossTerm::VolumePenalty => "gp3",
        LossTerm::VolumeAdversarial => "adv3",
    }
}

#[cfg(test)]
mod tests {
    use clap::Parser;
    use singrav::TrainConfig;

    use super::TrainOptions;

    /// `train`'s options alone, as the command line parses them.
    #[derive(clap::Parser)]
    struct Options {
        #[command(flatten)]
        options: TrainOptions,
    }

    fn config(args: &[&str]) -> TrainConfig {
        let parsed = Options::try_parse_from(std::iter::once("train").chain(args.iter().copied()));
        parsed.unwrap().options.config().unwrap()
    }

    #[test]
    fn presets_run_the_active_set_and_dense_turns_it_off() {
        let tiny = config(&["--preset", "tiny"]);
        assert_eq!(tiny.active_set.from_scale, Some(2));
        assert!(tiny.active_set.shell);
        let dense = config(&["--preset", "tiny", "--dense"]);
        assert_eq!(dense.active_set.from_scale, None);
        assert_eq!(config(&["--preset", "micro"]).active_set.from_scale, None);
        let margin_only = config(&["--preset", "small", "--set", "active_set.shell=false"]);
        assert_eq!(margin_only.active_set.from_scale, Some(2));
        assert!(!margin_only.active_set.shell);
    }

    #[test]
    fn the_reconstruction_fit_is_the_presets_unless_given() {
        let preset = TrainConfig::preset("tiny")
            .unwrap()
            .schedule
            .reconstruction_fit_steps;
        assert_eq!(
            config(&["--preset", "tiny"])
                .schedule
                .reconstruction_fit_steps,
            preset
        );
        let given = config(&["--preset", "tiny", "--reconstruction-fit", "500"]);
        assert_eq!(given.schedule.reconstruction_fit_steps, 500);
        let off = config(&["--preset", "tiny", "--reconstruction-fit", "0"]);
        assert_eq!(off.schedule.reconstruction_fit_steps, 0);
    }

    #[test]
    fn the_fitted_weight_is_the_configurations_else_10_with_a_fitted_volume() {
        assert_eq!(config(&["--preset", "tiny"]).losses.fitted, 0.0);
        let fit = config(&["--preset", "tiny", "--fit"]);
        assert_eq!(fit.losses.fitted, super::DEFAULT_LAMBDA_FITTED);
        let fitted = config(&["--fitted", "v.safetensors", "--lambda-fitted", "3"]);
        assert_eq!(fitted.losses.fitted, 3.0);
        let set = config(&["--fit", "--set", "losses.fitted=2"]);
        assert_eq!(set.losses.fitted, 2.0, "--set comes after the flags");
    }
}

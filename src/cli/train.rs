//! `volgen train DATASET --out RUN [--preset tiny] [--resume] [--vgg19 WEIGHTS]`: train
//! SinGRAV on a `transforms.json` RGB-D dataset, with a progress bar, a JSON-lines log and
//! checkpoints.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use rgbd_dataset::{Bounds, Dataset, DepthKind, LoadOptions, SceneBounds};
use singrav::train::{
    prepare, Control, Event, LossTerm, Progress, RunFit, RunOptions, StepLosses, TrainOutcome,
    Trainer,
};
use singrav::{RunDir, SinGrav, SwdFeatures, TrainConfig};

use super::fit::FitBar;
use super::settings::{names_setting, Settings};

/// Arguments of `volgen train`.
#[derive(Debug, clap::Args)]
pub struct TrainArgs {
    /// The dataset: a transforms.json or the directory holding it.
    dataset: PathBuf,
    /// The run directory: checkpoint, configuration, loss log and pictures (docs/training.md,
    /// "Files of a run").
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
    bounds: Option<Bounds>,
    /// Depth from a fit of the views (the paper's NeRF-depth), for photos without depth maps:
    /// fits the training views without depth (`volgen fit`'s defaults, 64^3; kept in the run
    /// and reused by --resume), renders its depth from every camera and trains with it, pixels
    /// the fit leaves thin left out of the depth loss. Replaces the dataset's own depth maps
    /// where it has some. Give it again with --resume.
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
    /// The preset the configuration starts from.
    #[arg(long, default_value = "tiny", value_parser = presets())]
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
    /// Weight of the colour-distribution loss of generated scenes at the 3D scales,
    /// `losses.colour_distribution` (sliced W2 between the pixel colours of a sample's rendering
    /// and the real view's; default: the preset's). `--lambda-colour` is its old name.
    #[arg(long, value_name = "W", alias = "lambda-colour")]
    pub lambda_colour_distribution: Option<f64>,
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
    /// Seed of every random draw (default: the preset's, 0).
    #[arg(long)]
    pub seed: Option<u64>,
    /// Also compare every 3D scale's reconstruction in 3D with this directly fitted volume
    /// (from `volgen fit`; copied into the run) instead of fitting one.
    #[arg(long, value_name = "VOLUME", conflicts_with = "fit")]
    pub fitted: Option<PathBuf>,
    /// Fit a volume to the dataset first (`volgen fit` at twice the finest 3D scale's edge, or
    /// at that edge for post-activated runs; kept in the run) and train against it as
    /// --fitted does. A configuration that compares with a fitted volume (`--set
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
    /// Set any setting of the configuration, by its dotted path in the run's configuration, to
    /// a JSON value, after the preset and the flags above: `--set losses.rgb=50 --set
    /// pyramid.channels=32`. Repeatable; a setting a flag above gives is refused.
    #[arg(long = "set", value_name = "PATH=VALUE")]
    pub settings: Vec<String>,
    /// Keep every N-th view (0, N, 2N, ...) out of training; `volgen eval` reports the
    /// reconstruction on them separately (fit against 3D consistency). Recorded in the run.
    #[arg(long, value_name = "N")]
    pub holdout: Option<usize>,
}

/// `--preset`'s values, each with what it is for (`--help` lists them).
fn presets() -> clap::builder::PossibleValuesParser {
    TrainConfig::PRESETS
        .map(|name| {
            let about = TrainConfig::preset_about(name).unwrap_or_default();
            clap::builder::PossibleValue::new(name).help(about)
        })
        .into()
}

/// The fitted-volume weight `--fitted` and `--fit` use on a configuration without one, unless told
/// otherwise.
pub const DEFAULT_LAMBDA_FITTED: f64 = 10.0;

impl TrainOptions {
    /// The configuration these options describe.
    pub fn config(&self) -> Result<TrainConfig> {
        self.flags()?.set(&self.settings)
    }

    /// The preset changed by the flags, each naming the settings it changes (`--set` comes
    /// after).
    pub fn flags(&self) -> Result<Settings> {
        let mut s = Settings::new(TrainConfig::preset(&self.preset)?);
        if let Some(scales) = self.scales {
            let paths = &[
                "pyramid.volume_sizes",
                "pyramid.image_sizes",
                "pyramid.samples",
                "schedule.scales",
                "schedule.scale_views",
            ];
            s.flag("--scales", paths, |c| {
                *c = c.clone().with_scales(scales)?;
                Ok(())
            })?;
        }
        if let Some(iterations) = self.iterations {
            s.flag("--iterations", &["schedule.scales"], |c| {
                *c = c.clone().with_iterations(iterations);
                Ok(())
            })?;
        }
        if self.no_swd {
            s.flag("--no-swd", &["ablations.use_swd"], |c| {
                c.ablations.use_swd = false;
                Ok(())
            })?;
        }
        if self.vgg19.is_some() {
            s.flag("--vgg19", &["losses.swd_features"], |c| {
                c.losses.swd_features = SwdFeatures::Vgg19;
                Ok(())
            })?;
        }
        if self.no_csg {
            s.flag("--no-csg", &["ablations.use_csg"], |c| {
                c.ablations.use_csg = false;
                Ok(())
            })?;
        }
        if self.no_depth {
            s.flag("--no-depth", &["ablations.use_depth"], |c| {
                c.ablations.use_depth = false;
                Ok(())
            })?;
        }
        if let Some(views) = self.reconstruction_views {
            s.flag("--reconstruction-views", &["schedule.scale_views"], |c| {
                *c = c.clone().with_reconstruction_views(views);
                Ok(())
            })?;
        }
        if self.dense {
            s.flag("--dense", &["active_set.from_scale"], |c| {
                c.active_set.from_scale = None;
                Ok(())
            })?;
        }
        if let Some(weight) = self.lambda_colour_distribution {
            let paths = &["losses.colour_distribution"];
            s.flag("--lambda-colour-distribution", paths, |c| {
                c.losses.colour_distribution = weight;
                Ok(())
            })?;
        }
        if let Some(layers) = self.layers {
            s.flag("--layers", &["pyramid.layers"], |c| {
                c.pyramid.layers = layers;
                Ok(())
            })?;
        }
        if let Some(rate) = self.learning_rate {
            s.flag("--learning-rate", &["schedule.learning_rate"], |c| {
                c.schedule.learning_rate = rate;
                Ok(())
            })?;
        }
        if self.no_opacity {
            let paths = &[
                "losses.opacity",
                "critics.opacity",
                "losses.height_profile",
                "losses.opacity_binary",
            ];
            s.flag("--no-opacity", paths, |c| {
                c.losses.opacity = 0.0;
                c.critics.opacity = false;
                c.losses.height_profile = 0.0;
                c.losses.opacity_binary = 0.0;
                Ok(())
            })?;
        }
        if let Some(seed) = self.seed {
            s.flag("--seed", &["run.seed"], |c| {
                c.run.seed = seed;
                Ok(())
            })?;
        }
        if let Some(weight) = self.lambda_fitted {
            s.flag("--lambda-fitted", &["losses.fitted"], |c| {
                c.losses.fitted = weight;
                Ok(())
            })?;
        } else if self.fitted.is_some() || self.fit {
            // Only a default weight, which `--set losses.fitted` may give instead.
            s.flag("--fit / --fitted", &[], |c| {
                if c.losses.fitted == 0.0 {
                    c.losses.fitted = DEFAULT_LAMBDA_FITTED;
                }
                Ok(())
            })?;
        }
        if let Some(weight) = self.lambda_volume_critic {
            s.flag("--lambda-volume-critic", &["losses.volume_critic"], |c| {
                c.losses.volume_critic = weight;
                Ok(())
            })?;
        }
        if self.volume_critic_colour {
            s.flag("--volume-critic-colour", &["critics.volume_colour"], |c| {
                c.critics.volume_colour = true;
                Ok(())
            })?;
        }
        if let Some(steps) = self.reconstruction_fit {
            let paths = &["schedule.reconstruction_fit_steps"];
            s.flag("--reconstruction-fit", paths, |c| {
                c.schedule.reconstruction_fit_steps = steps;
                Ok(())
            })?;
        }
        if let Some(every) = self.holdout {
            s.flag("--holdout", &["run.holdout"], |c| {
                c.run.holdout = Some(every);
                Ok(())
            })?;
        }
        Ok(s)
    }

    /// How the run goes beside its configuration: resume or not, the VGG-19 weights, a fitted
    /// volume given and the steps of the fit made otherwise.
    pub fn run_options(&self) -> RunOptions {
        RunOptions {
            resume: self.resume,
            vgg19_weights: self.vgg19.clone(),
            fitted_volume: self.fitted.clone(),
            fit_steps: self.fit_steps,
            ..RunOptions::default()
        }
    }
}

/// Trains as the arguments say.
pub fn run(args: &TrainArgs) -> Result<()> {
    let mut flags = args.options.flags()?;
    if args.bounds.is_some() {
        // Resolved on the dataset below.
        flags.flag("--bounds", &["run.bounds"], |_| Ok(()))?;
    }
    if args.depth_from_fit {
        flags.flag("--depth-from-fit", &["run.depth_from_fit"], |c| {
            c.run.depth_from_fit = true;
            Ok(())
        })?;
    }
    let mut config = flags.set(&args.options.settings)?;
    let auto = args.bounds == Some(Bounds::Auto);
    let depth_kind = if config.reads_depth_maps() || auto {
        args.depth_kind
    } else {
        // Nothing reads the depth maps: their kind need not be known.
        Some(DepthKind::None)
    };
    let dataset = load_dataset(&args.dataset, &config, depth_kind)?;
    match &args.bounds {
        Some(bounds) => config.run.bounds = Some(scene_bounds(bounds, &dataset)?),
        None if config.run.bounds.is_none() => warn_if_beyond_the_cube(&dataset),
        None => {}
    }
    if config.reads_depth_maps()
        && dataset.depth_kind() == DepthKind::None
        && !names_setting(&args.options.settings, "ablations.use_depth")
    {
        // Without depth maps the depth loss and the critics' depth channel have nothing to see.
        config.ablations.use_depth = false;
    }
    let options = RunOptions {
        depth_fit_steps: args.depth_fit_steps,
        ..args.options.run_options()
    };
    if options.resume && args.out.is_dir() && !RunDir::new(&args.out).has_checkpoint() {
        eprintln!(
            "{} holds no checkpoint yet: training from the beginning",
            args.out.display()
        );
    }
    train_with_progress(&config, &dataset, &args.out, &options)?;
    println!("trained model: {}", args.out.display());
    Ok(())
}

/// The scene's box `bounds` gives for `dataset`, printed with where the model's cube lies.
pub fn scene_bounds(bounds: &Bounds, dataset: &Dataset) -> Result<SceneBounds> {
    let scene = bounds.resolve(dataset)?;
    let cube = scene.cube();
    println!(
        "scene bounds {scene} (--bounds {bounds}); the model's cube [-1, 1]^3 is {:?}..{:?} in \
         the scene",
        cube.min.to_array(),
        cube.max.to_array()
    );
    Ok(scene)
}

/// Warns when the scene the depth maps show is not in the model's cube
/// ([`singrav::train::beyond_the_cube`]): trained without bounds, it would be cut off or
/// squeezed.
pub fn warn_if_beyond_the_cube(dataset: &Dataset) {
    if let Some(seen) = singrav::train::beyond_the_cube(dataset) {
        eprintln!(
            "warning: the depth maps' points span {seen}, beyond the model's cube [-1, 1]^3; \
             give --bounds auto (or the scene's box) to place the scene"
        );
    }
}

/// Loads and checks a dataset for training with `config`, its depth read as `depth_kind` when
/// given (else as the dataset says; [`DepthKind::None`]: not read), and reports the pixels left
/// out of the depth loss.
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
    if depth_kind == Some(DepthKind::None) {
        // Not asked for: nothing to report.
    } else if dataset.depth_kind() == DepthKind::None {
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

/// Trains with a progress bar (scale, step, losses, time left) and a line per scale, after the
/// fits the run needs first ([`prepare`]), each with a bar of its own and a line.
pub fn train_with_progress(
    config: &TrainConfig,
    dataset: &Dataset,
    run_dir: &Path,
    options: &RunOptions,
) -> Result<Box<SinGrav>> {
    let device = device()?;
    let run = RunDir::new(run_dir);
    let fit_bar = FitBar::new()?;
    let inputs = prepare(config, dataset, &run, options, &device, &mut |fit, p| {
        fit_bar.show(fit_name(fit), p);
    })
    .with_context(|| format!("training into {}", run_dir.display()))?;
    fit_bar.finish();
    for made in &inputs.made {
        eprintln!(
            "fitted {}^3 to {} in {:.1} s: {}",
            made.size,
            fit_name(made.fit),
            made.seconds,
            made.path.display()
        );
    }
    if let Some(coverage) = &inputs.depth_coverage {
        eprintln!(
            "depth from the fit: {} of {} foreground pixels ({:.1}%) are too thin in it and left \
             out of the depth loss",
            coverage.holes,
            coverage.foreground,
            100.0 * coverage.holes as f64 / coverage.foreground.max(1) as f64
        );
    }
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
    let outcome = Trainer::from_inputs(config, inputs, run_dir, &device)
        .and_then(|trainer| trainer.run(&mut observer))
        .with_context(|| format!("training into {}", run_dir.display()))?;
    bar.finish_and_clear();
    match outcome {
        TrainOutcome::Finished(model) => Ok(model),
        TrainOutcome::Stopped => bail!("training stopped before the last scale"),
    }
}

/// What a fit a run makes is of, in messages.
fn fit_name(fit: RunFit) -> &'static str {
    match fit {
        RunFit::DepthSource => "the views without depth for their depth",
        _ => "the dataset",
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

/// The losses of a step, compactly, by their short names: the RGB reconstruction first, then
/// every other term computed.
fn format_losses(l: &StepLosses) -> String {
    let first = LossTerm::Rgb;
    let mut parts = vec![format!(
        "{} {:.4}",
        first.short_name(),
        l.get(first).unwrap_or_default()
    )];
    for (term, value) in l.iter().filter(|(term, _)| *term != first) {
        parts.push(format!("{} {value:.3}", term.short_name()));
    }
    parts.join(" ")
}

#[cfg(test)]
mod tests {
    use clap::Parser;
    use singrav::TrainConfig;

    use super::{Settings, TrainOptions};

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

    /// `train`'s options as given, before `--set`.
    fn flags(args: &[&str]) -> Settings {
        let parsed = Options::try_parse_from(std::iter::once("train").chain(args.iter().copied()));
        parsed.unwrap().options.flags().unwrap()
    }

    #[test]
    fn a_set_of_what_a_flag_gives_is_an_error_naming_both() {
        for (flag, setting) in [
            (
                "--lambda-colour-distribution",
                "losses.colour_distribution=3",
            ),
            ("--lambda-colour", "losses.colour_distribution=3"),
            ("--seed", "run.seed=3"),
            ("--holdout", "run={}"),
            ("--layers", "pyramid.layers=4"),
        ] {
            let parsed = Options::try_parse_from(["train", flag, "4", "--set", setting]);
            let err = parsed.unwrap().options.config().unwrap_err().to_string();
            let named = if flag == "--lambda-colour" {
                "--lambda-colour-distribution"
            } else {
                flag
            };
            assert!(err.contains(named) && err.contains(setting), "{err}");
        }
        // A flag that only supplies a default leaves the setting to `--set`.
        let set = config(&["--fit", "--set", "losses.fitted=2"]);
        assert_eq!(set.losses.fitted, 2.0);
    }

    /// Every flag names each setting it changes, so what `--set` may change is known.
    #[test]
    fn every_flag_changes_only_the_settings_it_names() {
        let given = flags(&[
            "--preset",
            "small",
            "--scales",
            "3",
            "--no-swd",
            "--no-csg",
            "--no-depth",
            "--no-opacity",
            "--dense",
            "--lambda-colour-distribution",
            "7",
            "--reconstruction-views",
            "3",
            "--layers",
            "4",
            "--learning-rate",
            "0.01",
            "--iterations",
            "9",
            "--seed",
            "5",
            "--lambda-fitted",
            "2",
            "--lambda-volume-critic",
            "0.7",
            "--volume-critic-colour",
            "--reconstruction-fit",
            "11",
            "--holdout",
            "3",
        ]);
        let preset = TrainConfig::preset("small").unwrap();
        let changed = singrav::config::settings_that_differ(&preset, given.config());
        assert!(changed.len() >= 20, "{changed:?}");
        for change in changed {
            let path = change.split(' ').next().unwrap();
            assert!(given.flag_of(path).is_some(), "{path} changed by no flag");
        }
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
